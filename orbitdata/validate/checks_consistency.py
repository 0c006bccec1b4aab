"""Consistency: counts (card YAML, meta/info.json, data) and meta/stats.json against the data.

``meta/stats.json`` is recomputed in one streaming pass with memory flat in dataset size:

* count / mean / std / min / max are exact moments (sums in float64), so they are compared with
  ``rtol = 1e-6`` (the file keeps 7 significant digits) plus ``1e-7`` of the feature's range
  (float64 summation order, and std's ``sqrt(E[x^2] - mean^2)`` when std is ~0). Image moments
  come from every ``image_stride``-th train frame; the stride is read off the recorded count
  (the recipe's ``IMAGE_STRIDE`` if it fits), so data written with another stride still check.
* q01 / q99 were taken from a sample (every ``stride``-th row, at most ``QUANTILE_ROWS`` rows;
  images: every ``PIXEL_STRIDE``-th pixel), whose size older datasets did not record. So instead of rebuilding
  that sample, the check counts the values below and at ``q`` in the *whole* train split (exact,
  O(width) memory) and asks the fraction to be ``p`` within ``5 sqrt(p (1 - p) / n) + 2 / n``,
  ``n`` the smallest sample the generator may have used: five standard errors of a sample
  quantile, so ~600 quantiles give no false alarm, while a wrong or shuffled quantile moves the
  fraction by far more. Ties are handled: ``#{x < q} / N <= p + tol <= ...`` and
  ``#{x <= q} / N >= p - tol``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from orbitdata import schema as S
from orbitdata.codecs import (
    IMAGE_STRIDE,
    PIXEL_STRIDE,
    QUANTILE_ROWS,
    QUANTILES,
    SCALAR_FEATURES,
    VECTOR_FEATURES,
    stats_width,
)
from orbitdata.info import counts
from orbitdata.scenario.config import STATIC
from orbitdata.state import STATE_NAMES
from orbitdata.validate import checks as C
from orbitdata.validate.report import Sink

RTOL, RANGE_TOL = 1e-6, 1e-7


# ---- counts (quick) -----------------------------------------------------------------------
def _diff(a, b, path: str, out: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            _diff(a.get(key), b.get(key), f"{path}.{key}" if path else key, out)
    elif a != b:
        out.append(f"{path}: meta/info.json says {a}, the episodes table gives {b}")


def check_counts(
    info: dict | None,
    card: dict | None,
    episode_rows: list,
    data_rows: dict[str, int],
    episodes_complete: bool,
    sink: Sink,
    tier: str = STATIC,
) -> None:
    """Counts per split (and level, outcome) from the three places that state them."""
    frames_by_split = {s: 0 for s in S.SPLITS}
    for rel, n in data_rows.items():
        frames_by_split[S.SHARD_RE.match(rel).group(2)] += n
    table_frames = {s: sum(r.length for r in episode_rows if r.split == s) for s in S.SPLITS}
    table_eps = {s: sum(1 for r in episode_rows if r.split == s) for s in S.SPLITS}
    if episodes_complete:
        for split in S.SPLITS:
            if table_frames[split] != frames_by_split[split]:
                sink.add(
                    C.COUNTS,
                    f"{split}: the episodes table sums to {table_frames[split]} frames, the data "
                    f"shards hold {frames_by_split[split]} rows",
                    S.DATA_DIR,
                )
    if info is not None and episodes_complete:
        diffs: list[str] = []
        usable = [r for r in episode_rows if r.split in S.SPLITS and r.length is not None]
        _diff(
            info.get("counts"), counts(((r.split, r.level, r.outcome, r.length) for r in usable), tier), "counts", diffs
        )
        for d in diffs:
            sink.add(C.COUNTS, d, S.INFO_PATH)
    if card is None:
        return
    expected = {
        "default": (frames_by_split, "frames in the data shards"),
        "episodes": (table_eps, "rows in the episodes table"),
    }
    infos = card.get("dataset_info")
    infos = infos if isinstance(infos, list) else [infos] if isinstance(infos, dict) else []
    seen = set()
    for entry in infos:
        name = entry.get("config_name", "default") if isinstance(entry, dict) else None
        if name not in expected:
            continue
        seen.add(name)
        truth, what = expected[name]
        card_splits = {s.get("name"): s.get("num_examples") for s in entry.get("splits") or [] if isinstance(s, dict)}
        for split in sorted(set(card_splits) | {s for s, n in truth.items() if n}):
            if card_splits.get(split) != truth.get(split, 0):
                sink.add(
                    C.COUNTS,
                    f"dataset_info[{name}] says {split} has {card_splits.get(split)} examples, "
                    f"there are {truth.get(split, 0)} {what}",
                    S.CARD_PATH,
                )
    for name in sorted(set(expected) - seen):
        sink.add(C.COUNTS, f"the card's YAML has no dataset_info for config {name!r}", S.CARD_PATH)


# ---- stats (full) -------------------------------------------------------------------------
@dataclass(frozen=True)
class StatsPlan:
    """What a worker needs to recompute its share of meta/stats.json."""

    image_stride: int  # RGB statistics come from train frames whose index is a multiple of this
    quantiles: dict  # feature -> {"q01": array, "q99": array} from meta/stats.json

    @classmethod
    def build(cls, train_rows: int, stats: dict | None, image_pixels: int | None) -> "StatsPlan":
        quantiles = {}
        for name, width in ((n, stats_width(n)) for n in (*VECTOR_FEATURES, *SCALAR_FEATURES, S.IMAGE)):
            entry = (stats or {}).get(name)
            try:
                qs = {q: np.asarray(entry[q], dtype=np.float64).reshape(width) for q, _ in QUANTILES}
            except (KeyError, TypeError, ValueError, AttributeError):
                continue
            quantiles[name] = qs
        return cls(_image_stride(train_rows, stats, image_pixels), quantiles)


def _image_stride(train_rows: int, stats: dict | None, image_pixels: int | None) -> int:
    """The frame stride that explains the recorded image pixel count (IMAGE_STRIDE if it does)."""
    try:
        count = int(stats[S.IMAGE]["count"])
    except (KeyError, TypeError, ValueError):
        return IMAGE_STRIDE
    if not image_pixels or count % image_pixels or train_rows < 1:
        return IMAGE_STRIDE
    frames = count // image_pixels
    if frames < 1 or -(-train_rows // IMAGE_STRIDE) == frames:
        return IMAGE_STRIDE
    fits = [s for s in range(1, train_rows + 1) if -(-train_rows // s) == frames]
    return fits[0] if fits else IMAGE_STRIDE


def quantile_tolerance(p: float, sample: int) -> float:
    """Allowed |fraction below q - p| for a quantile taken from ``sample`` values (see module doc)."""
    sample = max(sample, 1)
    return 5.0 * math.sqrt(p * (1.0 - p) / sample) + 2.0 / sample


@dataclass
class Moments:
    """Exact moments plus counts around the recorded quantiles, mergeable across workers."""

    n: int = 0
    sum: np.ndarray | None = None
    sumsq: np.ndarray | None = None
    min: np.ndarray | None = None
    max: np.ndarray | None = None
    ranks: dict = field(default_factory=dict)  # "q01" -> (count below, count at or below), arrays

    def update(self, x: np.ndarray, quantiles: dict | None) -> None:
        """Add rows x (N, width); count them around the recorded quantiles (7 digits: 1e-6 slack)."""
        if not len(x):
            return
        part = Moments(len(x), x.sum(0), (x * x).sum(0), x.min(0), x.max(0))
        for q, _ in QUANTILES:
            if quantiles and q in quantiles:
                ref = quantiles[q]
                eps = 1e-6 * np.abs(ref)
                part.ranks[q] = ((x < ref - eps).sum(0), (x <= ref + eps).sum(0))
        self.merge(part)

    @classmethod
    def from_histogram(cls, hist: np.ndarray, quantiles: dict | None) -> "Moments":
        """Moments of uint8 image values / 255 from per-channel counts (C, 256): exact and cheap."""
        values = np.arange(256, dtype=np.float64) / 255.0
        n = int(hist[0].sum())
        m = cls()
        if n == 0:
            return m
        present = hist > 0
        m.n, m.sum, m.sumsq = n, hist @ values, hist @ (values * values)
        m.min = np.array([values[np.flatnonzero(row)[0]] for row in present])
        m.max = np.array([values[np.flatnonzero(row)[-1]] for row in present])
        for q, _ in QUANTILES:
            if quantiles and q in quantiles:
                ref = quantiles[q][:, None]
                eps = 1e-6 * np.abs(ref)
                m.ranks[q] = ((hist * (values < ref - eps)).sum(1), (hist * (values <= ref + eps)).sum(1))
        return m

    def merge(self, other: "Moments") -> None:
        if other.n == 0:
            return
        if self.n == 0:
            self.n, self.sum, self.sumsq, self.min, self.max = other.n, other.sum, other.sumsq, other.min, other.max
        elif other.n:
            self.n += other.n
            self.sum, self.sumsq = self.sum + other.sum, self.sumsq + other.sumsq
            self.min, self.max = np.minimum(self.min, other.min), np.maximum(self.max, other.max)
        for q, (lo, hi) in other.ranks.items():
            a, b = self.ranks.get(q, (0, 0))
            self.ranks[q] = (a + lo, b + hi)


def merge_moments(total: dict[str, Moments], part: dict[str, Moments]) -> None:
    for name, m in part.items():
        total.setdefault(name, Moments()).merge(m)


def check_stats(stats: dict, measured: dict[str, Moments], train_rows: int, sink: Sink) -> None:
    """meta/stats.json against moments recomputed from the train split."""
    sample_rows = min(train_rows, QUANTILE_ROWS)  # the smallest sample the generator may have used
    expected = set(VECTOR_FEATURES) | set(SCALAR_FEATURES) | ({S.IMAGE} if S.IMAGE in measured else set())
    for name in sorted(set(stats) - expected):
        sink.add(C.STATS, f"feature {name!r} is not one stats are computed for", S.STATS_PATH)
    for name in sorted(expected):
        m, entry = measured.get(name), stats.get(name)
        if not isinstance(entry, dict):
            sink.add(C.STATS, f"no statistics for {name!r}; regenerate meta with `orbitdata shard`", S.STATS_PATH)
            continue
        if m is None or m.n == 0:
            continue
        width = len(m.sum)
        names = STATE_NAMES if name == S.STATE else [str(i) for i in range(width)]
        if entry.get("count") != m.n:
            sink.add(C.STATS, f"{name} count is {entry.get('count')}, the train split has {m.n} values", S.STATS_PATH)
        with np.errstate(invalid="ignore", over="ignore"):  # NaN/Inf in the data: values.finite says where
            mean = m.sum / m.n
            values = {
                "mean": mean,
                "std": np.sqrt(np.maximum(m.sumsq / m.n - mean * mean, 0.0)),
                "min": m.min,
                "max": m.max,
            }
            scale = np.maximum(np.abs(m.min), np.abs(m.max))
        for key, ours in values.items():
            try:
                theirs = np.asarray(entry[key], dtype=np.float64).reshape(width)
            except (KeyError, TypeError, ValueError):
                sink.add(C.STATS, f"{name}.{key} is missing or not {width} numbers", S.STATS_PATH)
                continue
            with np.errstate(invalid="ignore"):
                bad = np.flatnonzero(~(np.abs(theirs - ours) <= RTOL * np.abs(ours) + RANGE_TOL * scale))
            for i in bad[:3]:
                sink.add(
                    C.STATS,
                    f"{name}[{names[i]}].{key} is {theirs[i]:.7g}, the train split gives {ours[i]:.7g}",
                    S.STATS_PATH,
                )
        for q, p in QUANTILES:
            if q not in m.ranks:
                sink.add(C.STATS, f"{name}.{q} is missing or not {width} numbers", S.STATS_PATH)
                continue
            below, at_or_below = m.ranks[q]
            # The sample size is recorded (q_count) since it became bounded; older files
            # sampled every 97th image pixel and at most QUANTILE_ROWS rows.
            sample = entry.get("q_count") or (m.n // PIXEL_STRIDE if name == S.IMAGE else sample_rows)
            tol = quantile_tolerance(p, sample)
            bad = np.flatnonzero((below / m.n > p + tol) | (at_or_below / m.n < p - tol))
            for i in bad[:3]:
                sink.add(
                    C.STATS,
                    f"{name}[{names[i]}].{q} = {entry[q][i]:.7g} is not the {p:g} quantile of the "
                    f"train split: {below[i] / m.n:.2%} of the values lie below it, "
                    f"{at_or_below[i] / m.n:.2%} at or below (tolerance {tol:.2%})",
                    S.STATS_PATH,
                )
