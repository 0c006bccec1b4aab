"""Structure, integrity and schema: which files are there, whether they open, hash and match v1.

These checks read only metadata (meta/*.json, the card header, Parquet footers) and file bytes
for the sha256, so they are all part of ``--quick``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import yaml

from orbitdata import schema as S
from orbitdata.info import FileEntry
from orbitdata.scenario.config import STATIC, TIERS
from orbitdata.validate import checks as C
from orbitdata.validate.report import Sink

# Written by Hub clients or git, never part of a dataset: a downloaded snapshot may carry them.
TOLERATED_FILES = (".gitattributes", ".gitignore")
TOLERATED_DIRS = (".git", ".cache", ".huggingface")
REQUIRED = (S.CARD_PATH, S.INFO_PATH, S.STATS_PATH)


@dataclass
class ParquetFooter:
    rel: str
    kind: str  # "data" or "episodes"
    split: str
    num_rows: int
    row_groups: list[int]  # rows per row group
    schema_ok: bool
    table: pa.Table | None = None  # episodes shards: the whole (small) table, once read


@dataclass
class Layout:
    """What the quick pass learned about a dataset folder; the full pass builds on it."""

    root: Path
    info: dict | None = None
    stats: dict | None = None
    card: dict | None = None  # the card's YAML header
    present: list[str] = field(default_factory=list)  # every file (relative, posix), tolerated ones excluded
    footers: dict[str, ParquetFooter] = field(default_factory=dict)  # readable Parquet shards

    def shards(self, kind: str, split: str | None = None) -> list[ParquetFooter]:
        return sorted(
            (f for f in self.footers.values() if f.kind == kind and (split is None or f.split == split)),
            key=lambda f: f.rel,
        )


def scan(root: Path) -> list[str]:
    """Relative posix paths of every file under root, minus what Hub clients and git add."""
    out = []
    for dirpath, dirnames, filenames in os.walk(root):
        rel_dir = Path(dirpath).relative_to(root)
        if rel_dir == Path("."):
            dirnames[:] = [d for d in dirnames if d not in TOLERATED_DIRS]
        for name in filenames:
            rel = (rel_dir / name).as_posix()
            if rel not in TOLERATED_FILES:
                out.append(rel)
    return sorted(out)


def drop_broken_links(layout: Layout, sink: Sink) -> None:
    """Links to nothing are reported and left out of ``layout.present`` (a listed one is then missing)."""
    broken = [rel for rel in layout.present if not (layout.root / rel).exists()]
    for rel in broken:
        sink.add(C.UNREADABLE, "a link to nothing: restore its target, or delete it", rel)
    layout.present = [rel for rel in layout.present if rel not in set(broken)]


def load_json(root: Path, rel: str, sink: Sink) -> dict | None:
    path = root / rel
    if not path.exists():
        return None  # reported by check_presence
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        sink.add(C.UNREADABLE, f"cannot read: {exc.strerror or exc}; check its permissions", rel)
        return None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        sink.add(C.UNREADABLE, f"not valid JSON ({exc}); regenerate meta with `orbitdata shard`", rel)
        return None
    if not isinstance(data, dict):
        sink.add(C.UNREADABLE, f"expected a JSON object, got {type(data).__name__}", rel)
        return None
    return data


def load_card(root: Path, sink: Sink) -> dict | None:
    """The YAML header of README.md (between the first two '---' lines)."""
    path = root / S.CARD_PATH
    if not path.exists():
        return None
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        sink.add(C.UNREADABLE, f"cannot read the dataset card: {exc}", S.CARD_PATH)
        return None
    parts = text.split("---", 2) if text.startswith("---") else []
    if len(parts) < 3:
        sink.add(
            C.UNREADABLE, "the card has no YAML header (--- ... ---); the Hub needs it to load configs", S.CARD_PATH
        )
        return None
    try:
        header = yaml.safe_load(parts[1])
    except yaml.YAMLError as exc:
        sink.add(C.UNREADABLE, f"the card's YAML header does not parse: {str(exc).splitlines()[0]}", S.CARD_PATH)
        return None
    if not isinstance(header, dict):
        sink.add(C.UNREADABLE, "the card's YAML header is not a mapping", S.CARD_PATH)
        return None
    return header


def check_version(info: dict, sink: Sink) -> None:
    version = info.get("schema_version")
    if not S.readable_schema(version):
        sink.add(
            C.VERSION,
            f"schema_version {version!r} is not one this orbitdata reads "
            f"({S.SCHEMA_VERSION.split('.')[0]}.x); checked against {S.SCHEMA_VERSION} anyway. "
            "Upgrade orbitdata, or regenerate the dataset",
            S.INFO_PATH,
        )


def tier_of(info: dict | None, sink: Sink) -> str:
    """The scenario tier that meta/info.json records (``config.scenario.tier``; a static record
    leaves it out). An unknown tier is reported and checked as static."""
    config = (info or {}).get("config")
    scenario = config.get("scenario") if isinstance(config, dict) else None
    tier = scenario.get("tier", STATIC) if isinstance(scenario, dict) else STATIC
    if tier not in TIERS:
        sink.add(
            C.COLUMNS,
            f"config.scenario.tier {tier!r} is not a tier this orbitdata knows ({', '.join(TIERS)}); "
            "checked as static. Upgrade orbitdata, or regenerate the dataset",
            S.INFO_PATH,
        )
        return STATIC
    return tier


def check_presence(layout: Layout, sink: Sink) -> None:
    """Missing files (named by the layout or info.json) and extra ones (named by neither)."""
    present = set(layout.present)
    listed = set((layout.info or {}).get("files", {}))
    for rel in REQUIRED:
        if rel not in present:
            hint = (
                "the dataset is incomplete: run `orbitdata generate` again to finish it"
                if rel == S.INFO_PATH
                else "regenerate meta and the card with `orbitdata shard`"
            )
            sink.add(C.MISSING, f"required file is missing; {hint}", rel)
    unlisted_shards = any(S.SHARD_RE.match(rel) for rel in present - listed)
    for rel in sorted(listed - present):
        if rel not in REQUIRED:
            hint = (
                "an interrupted re-shard? run `orbitdata shard` again"
                if unlisted_shards and S.SHARD_RE.match(rel)
                else "download or regenerate it"
            )
            sink.add(C.MISSING, f"listed in meta/info.json but missing; {hint}", rel)
    _check_shard_sets(layout, sink)
    allowed = listed | set(REQUIRED)
    for rel in sorted(present - allowed):
        name = rel.rsplit("/", 1)[-1]
        if rel.startswith(f"{S.PARTS_DIR}/"):
            hint = "leftover of an unfinished generation: run `orbitdata generate` again to finish it"
        elif name.startswith(".tmp-"):
            hint = "leftover of an interrupted write: delete it"
        elif layout.info is None:
            continue  # without info.json there is no list to compare with
        elif S.SHARD_RE.match(rel):
            hint = "a shard meta/info.json does not list (an interrupted re-shard leaves these): run `orbitdata shard` again"
        else:
            hint = "not in meta/info.json: delete it, or re-shard with `orbitdata shard` if it belongs"
        sink.add(C.EXTRA, hint, rel)


def _check_shard_sets(layout: Layout, sink: Sink) -> None:
    """Every data/episodes shard series must be complete: i-of-N for all i < N, one N."""
    series: dict[tuple[str, str], dict[int, set[int]]] = {}
    for rel in layout.present:
        m = S.SHARD_RE.match(rel)
        if m:
            kind, split, i, n = m.group(1), m.group(2), int(m.group(3)), int(m.group(4))
            series.setdefault((kind, split), {}).setdefault(n, set()).add(i)
    splits = set((layout.info or {}).get("counts", {}).get("splits", {})) or {s for _, s in series}
    for kind in (S.DATA_DIR, S.EPISODES_DIR):
        for split in sorted(splits):
            if (kind, split) not in series:
                sink.add(
                    C.MISSING,
                    f"no {kind} shard for the {split} split (expected "
                    f"{S.shard_path(kind, split, 0, 1)} or a numbered series)",
                    kind,
                )
    for (kind, split), by_count in sorted(series.items()):
        if len(by_count) > 1:
            sink.add(
                C.EXTRA,
                f"{kind}/{split} shards from different layouts (of {sorted(by_count)}): "
                "re-shard with `orbitdata shard`",
                kind,
            )
        for n, have in sorted(by_count.items()):
            for i in sorted(set(range(n)) - have):
                sink.add(C.MISSING, "shard missing from its series", S.shard_path(kind, split, i, n))


def sha256_task(root: str, rel: str) -> tuple[str, str | None, int, str | None]:
    """(rel, sha256, bytes, error): runs in a worker process."""
    try:
        entry = FileEntry.of(Path(root) / rel)
    except OSError as exc:
        return rel, None, 0, exc.strerror or str(exc)
    return rel, entry.sha256, entry.bytes, None


def check_hash(info: dict, rel: str, digest: str | None, size: int, error: str | None, sink: Sink) -> None:
    if error is not None:
        sink.add(C.UNREADABLE, f"cannot read: {error}; check its permissions", rel)
        return
    expected = info.get("files", {}).get(rel)
    if not isinstance(expected, dict):
        return
    if expected.get("bytes") is not None and expected["bytes"] != size:
        sink.add(
            C.SHA256,
            f"{size} bytes, meta/info.json says {expected['bytes']}: the file is truncated or was "
            "changed; download it again or regenerate the dataset",
            rel,
        )
    elif expected.get("sha256") != digest:
        recorded = str(expected.get("sha256"))[:12]
        sink.add(
            C.SHA256,
            f"sha256 {digest[:12]}... differs from meta/info.json ({recorded}...): the file was "
            "changed or corrupted; download it again or regenerate the dataset",
            rel,
        )


def open_footer(root: Path, rel: str, sink: Sink, tier: str = STATIC) -> ParquetFooter | None:
    """Read one shard's footer and compare its schema with v1's for the dataset's ``tier``."""
    m = S.SHARD_RE.match(rel)
    assert m, rel
    kind, split = m.group(1), m.group(2)
    try:
        pf = pq.ParquetFile(root / rel)
    except OSError as exc:
        if isinstance(exc, PermissionError):
            sink.add(C.UNREADABLE, f"cannot read: {exc.strerror}; check its permissions", rel)
        else:
            sink.add(
                C.CORRUPT,
                f"not a readable Parquet file ({exc}); it is truncated or corrupt: "
                "download it again or regenerate the dataset",
                rel,
            )
        return None
    except Exception as exc:  # pyarrow raises ArrowInvalid & co. for a bad footer
        sink.add(
            C.CORRUPT,
            f"bad Parquet footer ({type(exc).__name__}: {exc}); download it again or regenerate the dataset",
            rel,
        )
        return None
    expected = S.step_schema(tier) if kind == S.DATA_DIR else S.episode_schema(tier)
    ok = check_schema(rel, pf.schema_arrow, expected, sink, tier)
    md = pf.metadata
    rows = [md.row_group(i).num_rows for i in range(md.num_row_groups)]
    return ParquetFooter(rel, kind, split, md.num_rows, rows, ok)


def check_schema(rel: str, actual: pa.Schema, expected: pa.Schema, sink: Sink, tier: str = STATIC) -> bool:
    ok = True
    names = set(actual.names)
    for f in expected:
        if f.name not in names:
            sink.add(C.COLUMNS, f"column {f.name!r} is missing (expected {f.type})", rel)
            ok = False
        elif not actual.field(f.name).type.equals(f.type):
            sink.add(C.COLUMNS, f"column {f.name!r} is {actual.field(f.name).type}, expected {f.type}", rel)
            ok = False
    for name in actual.names:
        if expected.get_field_index(name) < 0:
            what = "" if tier == STATIC else f" for the {tier} tier"
            sink.add(C.COLUMNS, f"unexpected column {name!r}: not part of schema {S.SCHEMA_VERSION}{what}", rel)
            ok = False
    if ok and actual.names != expected.names:
        sink.add(C.COLUMNS, f"columns are out of order: {actual.names}", rel)
    return ok
