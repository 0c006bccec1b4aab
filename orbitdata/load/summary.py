"""The data behind ``orbitdata info``: counts, episode lengths, sizes and how a dataset was made.

A dataset is a local folder or a Hugging Face Hub dataset repo id. Everything comes from
``meta/info.json`` and the (small) episodes shards; no frame is read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from orbitdata import schema as S
from orbitdata.info import Info
from orbitdata.load.source import hub_file, local_folder, read_info

LENGTH_BINS = 10  # histogram bins over [0, max_steps]


def read_source(source: str | Path) -> tuple[Info, pa.Table, str]:
    """(info, episodes table, where) for a local folder or a Hub repo id."""
    info = read_info(source)
    folder = local_folder(source)
    rels = [rel for rel in sorted(info.files) if rel.startswith(S.EPISODES_DIR + "/")]
    if folder is None:
        files = [hub_file(str(source), rel) for rel in rels]
        where = f"hf://datasets/{source}"
    else:
        files = [folder / rel for rel in rels]
        where = str(folder)
    missing = [str(f) for f in files if not Path(f).exists()]
    if missing or not files:
        raise FileNotFoundError(
            f"episodes shards {missing or '(none listed in meta/info.json)'} are missing "
            f"from {where}; run `orbitdata validate` on it"
        )
    columns = [S.SPLIT, S.LEVEL, S.OUTCOME, S.LENGTH]
    episodes = pa.concat_tables([pq.read_table(f, columns=columns) for f in files])
    return info, episodes, where


def length_stats(lengths: np.ndarray) -> dict:
    """min / p10 / median / mean / p90 / max of episode lengths in frames."""
    if not len(lengths):
        return {"episodes": 0}
    q = np.percentile(lengths, [10, 50, 90])
    return {
        "episodes": int(len(lengths)),
        "min": int(lengths.min()),
        "p10": round(float(q[0]), 1),
        "median": round(float(q[1]), 1),
        "mean": round(float(lengths.mean()), 1),
        "p90": round(float(q[2]), 1),
        "max": int(lengths.max()),
    }


def lengths_summary(episodes: pa.Table, max_steps: int) -> dict:
    """Length statistics overall, per level and per outcome, and a histogram per level."""
    length = np.asarray(episodes.column(S.LENGTH).to_numpy(), dtype=np.int64)
    level = np.asarray(episodes.column(S.LEVEL).to_pylist())
    outcome = np.asarray(episodes.column(S.OUTCOME).to_pylist())
    edges = np.linspace(0, max(max_steps, int(length.max(initial=1))), LENGTH_BINS + 1)
    return {
        "all": length_stats(length),
        "by_level": {lv: length_stats(length[level == lv]) for lv in S.LEVELS if (level == lv).any()},
        "by_outcome": {o: length_stats(length[outcome == o]) for o in S.DYNAMIC_OUTCOMES if (outcome == o).any()},
        "histogram": {
            "edges": [round(float(e), 3) for e in edges],
            "by_level": {
                lv: np.histogram(length[level == lv], edges)[0].tolist() for lv in S.LEVELS if (level == lv).any()
            },
            "by_outcome": {
                o: np.histogram(length[outcome == o], edges)[0].tolist()
                for o in S.DYNAMIC_OUTCOMES
                if (outcome == o).any()
            },
        },
    }


def sizes_summary(info: Info) -> dict:
    """Bytes per folder and split, from the file list in info.json."""
    out: dict = {"data": {}, "episodes": {}, "other": {}}
    for rel, entry in sorted(info.files.items()):
        folder, _, name = rel.partition("/")
        if folder in (S.DATA_DIR, S.EPISODES_DIR) and name:
            split = name.split("-")[0]
            out[folder][split] = out[folder].get(split, 0) + entry.bytes
        else:
            out["other"][rel] = entry.bytes
    out["files"] = len(info.files)
    out["total"] = info.bytes
    frames = info.counts.get("frames", 0)
    out["bytes_per_frame"] = round(out["total"] / frames) if frames else None
    return out


def _flatten(d: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in d.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def outcome_rates(counts: dict) -> dict:
    """Share of each outcome per level, over all splits (the outcomes the counts name: their tier's)."""
    rates = {}
    for level in S.LEVELS:
        per = [s["levels"][level] for s in counts.get("splits", {}).values() if level in s.get("levels", {})]
        n = sum(p["episodes"] for p in per)
        names = [o for o in S.DYNAMIC_OUTCOMES if o in S.OUTCOMES or any(o in p["outcomes"] for p in per)]
        if n:
            rates[level] = {o: round(sum(p["outcomes"].get(o, 0) for p in per) / n, 4) for o in names}
    return rates


def summarize(source: str | Path) -> dict:
    """Everything ``orbitdata info`` shows, as plain JSON-able data."""
    info, episodes, where = read_source(source)
    config = info.config
    sim = config.get("sim", {})
    counts = info.counts
    return {
        "source": where,
        "schema_version": info.schema_version,
        "codebase_version": info.codebase_version,
        "tier": info.tier,
        "fps": info.fps,
        "dt": info.dt,
        "root_seed": info.root_seed,
        "image_size": info.image_size,
        "episodes": counts.get("episodes"),
        "steps": counts.get("frames"),
        "counts": counts,
        "outcome_rates": outcome_rates(counts),
        "lengths": lengths_summary(episodes, int(info.max_steps or 0)),
        "sizes": sizes_summary(info),
        "parameters": {
            "sim": _flatten(sim),
            "hardware": {"wrench_rank": info.hardware.get("wrench_rank")},
            "pilots": _flatten(config.get("pilots", {})),
            "scenario": _flatten(config.get("scenario", {})),
            "dataset": _flatten(config.get("dataset", {})),
        },
    }
