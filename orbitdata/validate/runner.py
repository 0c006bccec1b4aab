"""``validate``: run every check on a dataset folder and return a :class:`Report`.

Order of work: metadata and the file list (driver), sha256 of every file (pool), Parquet footers
and the episodes table (driver), then, in full mode, every row group of every data shard (pool)
with the seams between row groups, the episode runs and the statistics finished in the driver.
Results are consumed in submission order, so the report is the same whatever ``workers`` is,
and at most ``2 * workers`` tasks are in flight, so memory does not grow with the dataset.
Workers are spawned (not forked), so a script that calls ``validate`` with several workers needs
the usual ``if __name__ == "__main__":`` guard.
"""

from __future__ import annotations

import bisect
import multiprocessing
import os
import time
from collections import deque
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import pyarrow.parquet as pq

from orbitdata import schema as S
from orbitdata.info import Info
from orbitdata.load.source import local_folder
from orbitdata.scenario.config import DYNAMIC, STATIC
from orbitdata.validate import checks as C
from orbitdata.validate.checks_consistency import Moments, StatsPlan, check_counts, check_stats, merge_moments
from orbitdata.validate.checks_dynamic import Flag, Physics, merge_flags, pose_model, thrust_flags
from orbitdata.validate.checks_episodes import (
    EpisodeRow,
    check_file_edges,
    check_row_ranges,
    check_runs,
    check_table,
    check_transitions,
    episode_rows,
)
from orbitdata.validate.checks_images import Camera
from orbitdata.validate.checks_structure import (
    Layout,
    check_hash,
    check_presence,
    check_version,
    drop_broken_links,
    load_card,
    load_json,
    open_footer,
    scan,
    sha256_task,
    tier_of,
)
from orbitdata.validate.checks_values import check_episode_floats, check_steps
from orbitdata.validate.diagnose_dynamic import diagnose
from orbitdata.validate.dynamic_record import EpisodeRecord, episode_records
from orbitdata.validate.report import DEFAULT_CAP, Report, Sink
from orbitdata.validate.rowgroup import FileContext, RowGroupResult, RowGroupTask, check_row_group, init_worker


@dataclass(frozen=True)
class ValidateOptions:
    """How to validate.

    Attributes:
        quick: structure, integrity, schema and counts only: file list, sha256, Parquet footers,
            the episodes table and metadata; no data pages or images are decoded.
        workers: processes for hashing and row groups; 1 = in this process; 0 = all cores, but
            no more than one per ``FRAMES_PER_WORKER`` frames (a worker takes ~1 s to start,
            the time it needs to check that many frames).
        max_per_check: findings listed per check; the rest are counted.
    """

    quick: bool = False
    workers: int = 0
    max_per_check: int = DEFAULT_CAP

    def __post_init__(self) -> None:
        if self.workers < 0:
            raise ValueError(f"workers must be >= 0 (0 = all cores), got {self.workers}")
        if self.max_per_check < 1:
            raise ValueError(f"max_per_check must be >= 1, got {self.max_per_check}")


FRAMES_PER_WORKER = 2000
Progress = Callable[[str, int, int], None]  # (phase, done, total)


class _Pool:
    """Ordered, bounded map over a process pool (or in-process for one worker)."""

    def __init__(self, workers: int):
        self.workers = workers
        self.pool = None
        if workers > 1:
            # spawn: the driver already runs pyarrow threads, and forking a threaded process is unsafe.
            ctx = multiprocessing.get_context("spawn")
            self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=init_worker)

    def map(self, fn, tasks: Iterable) -> Iterator:
        if self.pool is None:
            for task in tasks:
                yield fn(task)
            return
        pending: deque = deque()
        for task in tasks:
            pending.append(self.pool.submit(fn, task))
            if len(pending) >= 2 * self.workers:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)


def _auto_workers(root: Path) -> int:
    frames = 0
    for path in sorted((root / S.DATA_DIR).glob("*.parquet")):
        try:
            frames += pq.ParquetFile(path).metadata.num_rows
        except Exception:
            continue  # reported later; for sizing the pool a guess will do
    return max(1, min(os.cpu_count() or 1, frames // FRAMES_PER_WORKER))


def _sha_task(args: tuple[str, str]):
    return sha256_task(*args)


def validate(
    root: str | Path, options: ValidateOptions = ValidateOptions(), progress: Progress | None = None
) -> Report:
    """Check the dataset in ``root`` against the contract. Raises only if ``root`` is not a folder."""
    root = local_folder(root, repo_ok=False)
    start = time.monotonic()
    workers = options.workers or _auto_workers(root)
    sink = Sink(options.max_per_check)
    report = Report(str(root), "quick" if options.quick else "full", sink, workers=workers)
    layout = Layout(root, present=scan(root))
    drop_broken_links(layout, sink)
    layout.info = load_json(root, S.INFO_PATH, sink)
    layout.stats = load_json(root, S.STATS_PATH, sink)
    layout.card = load_card(root, sink)
    if layout.info is not None:
        check_version(layout.info, sink)
        damaged = Info.field_problems(layout.info)
        if damaged:  # checked as an unreadable record: nothing below reads its fields
            sink.add(
                C.UNREADABLE,
                f"{'; '.join(damaged)}: the dataset's record is damaged; download the dataset again, or "
                "regenerate it with the command its README gives",
                S.INFO_PATH,
            )
            layout.info = None
    tier = tier_of(layout.info, sink)
    report.checks = C.checks_for(tier)
    check_presence(layout, sink)
    report.files = len(layout.present)
    report.bytes = sum((root / rel).stat().st_size for rel in layout.present)

    pool = _Pool(workers)
    try:
        _check_hashes(layout, pool, sink, progress)
        rows = _check_metadata(layout, sink, tier)
        dynamic = _dynamic(layout, sink, report) if tier != STATIC else None
        report.episodes = len(rows)
        report.frames = sum(f.num_rows for f in layout.shards(S.DATA_DIR))
        if options.quick:
            for check in report.checks:
                if not check.quick:
                    report.skipped[check.name] = "full mode only (run without --quick)"
        else:
            _check_rows(layout, rows, pool, sink, report, progress, dynamic)
    finally:
        pool.close()
    report.seconds = time.monotonic() - start
    return report


def _check_hashes(layout: Layout, pool: _Pool, sink: Sink, progress: Progress | None) -> None:
    if layout.info is None:
        return
    present = set(layout.present)
    listed = [rel for rel in sorted(layout.info.get("files", {})) if rel in present]
    for i, (rel, digest, size, error) in enumerate(pool.map(_sha_task, [(str(layout.root), r) for r in listed])):
        check_hash(layout.info, rel, digest, size, error, sink)
        if progress:
            progress("sha256", i + 1, len(listed))


def _check_metadata(layout: Layout, sink: Sink, tier: str) -> list[EpisodeRow]:
    """Footers, schemas, the episodes table and the counts: everything --quick reads."""
    for rel in layout.present:
        if S.SHARD_RE.match(rel):
            footer = open_footer(layout.root, rel, sink, tier)
            if footer is not None:
                layout.footers[rel] = footer
    rows: list[EpisodeRow] = []
    split_of_file = {}
    complete = True
    for footer in layout.shards(S.EPISODES_DIR):
        if not footer.schema_ok:
            complete = False
            continue
        try:
            table = pq.read_table(layout.root / footer.rel)
        except Exception as exc:
            sink.add(
                C.CORRUPT,
                f"does not decode ({type(exc).__name__}: {str(exc)[:160]}); download it again or "
                "regenerate the dataset",
                footer.rel,
            )
            complete = False
            continue
        split_of_file[footer.rel] = footer.split
        rows += episode_rows(table, footer.rel)
        footer.table = table  # kept for the full pass (small: one row per episode)
    config = (layout.info or {}).get("config") or {}
    max_steps = (config.get("sim") or {}).get("max_steps")
    check_table(rows, split_of_file, max_steps, sink, tier)
    data_rows = {f.rel: f.num_rows for f in layout.shards(S.DATA_DIR)}
    complete = complete and all(f.schema_ok for f in layout.shards(S.DATA_DIR))
    if complete:
        check_row_ranges(rows, data_rows, sink)
    check_counts(layout.info, layout.card, rows, data_rows, complete, sink, tier)
    return rows


@dataclass
class _Dynamic:
    """The dynamic tier's part of a full validation: the records, and the episodes flagged so far."""

    physics: Physics | None  # None: the config does not say how to fly the body; only the records are checked
    records: dict[int, EpisodeRecord]
    thrust: dict[int, Flag]
    debris: dict[int, Flag]


def _dynamic(layout: Layout, sink: Sink, report: Report) -> _Dynamic:
    """The dynamic tier's episode records (``dynamics.record``, quick) and the simulator settings."""
    from orbitdata.config import GenerationConfig

    records: dict[int, EpisodeRecord] = {}
    for footer in layout.shards(S.EPISODES_DIR):
        if footer.table is not None:
            records |= episode_records(footer.table, footer.rel, sink)
    try:
        sim = GenerationConfig.from_dict((layout.info or {}).get("config") or {}).sim
        physics = Physics(sim.cubesat, sim.dt, sim.substeps)
    except (ValueError, TypeError) as exc:
        physics = None
        for check in (C.DYN_THRUST, C.DYN_DEBRIS, C.DYN_CW):
            report.skipped[check] = f"meta/info.json's config does not parse ({str(exc)[:120]})"
    return _Dynamic(physics, records, {}, {})


def _task_records(records: list[EpisodeRecord], ends: list[int], first: int, stop: int) -> dict[int, EpisodeRecord]:
    """The records (of one file, sorted by their row_end ``ends``) whose rows overlap rows [first, stop)."""
    out = {}
    for r in records[bisect.bisect_right(ends, first) :]:
        if r.row_start >= stop:
            break
        out[r.index] = r
    return out


def _check_rows(
    layout: Layout,
    rows: list[EpisodeRow],
    pool: _Pool,
    sink: Sink,
    report: Report,
    progress: Progress | None,
    dynamic: _Dynamic | None = None,
) -> None:
    """The full pass: every row group of every data shard, then seams, runs and stats."""
    for footer in layout.shards(S.EPISODES_DIR):
        if footer.table is not None:
            check_episode_floats(footer.table, footer.rel, sink)
    info = layout.info or {}
    sim = (info.get("config") or {}).get("sim") or {}
    dt = float(info.get("dt", S.DT))
    substeps = int(sim.get("substeps", 8))
    camera = Camera.from_info(layout.info)
    if camera is None:
        for check in (C.SIZE, C.DEPTH_RANGE, C.DEPTH_LOW):
            report.skipped[check] = "meta/info.json does not give the image shape and depth range"
    by_index = {r.index: r for r in rows}
    train = [f for f in layout.shards(S.DATA_DIR, "train") if f.schema_ok]
    train_rows = sum(f.num_rows for f in train)
    pixels = camera.height * camera.width if camera else None
    plan = StatsPlan.build(train_rows, layout.stats, pixels) if layout.stats is not None else None
    if plan is None:
        report.skipped[C.STATS] = "meta/stats.json is missing or unreadable"

    files = [f for f in layout.shards(S.DATA_DIR) if f.schema_ok]
    physics = dynamic.physics if dynamic is not None else None
    tasks, train_row = [], 0
    for footer in files:
        in_file = sorted(
            (r for r in dynamic.records.values() if r.data_file == footer.rel) if physics else (),
            key=lambda r: (r.row_end, r.row_start),
        )
        ends = [r.row_end for r in in_file]
        outcomes = {r.index: r.outcome for r in rows if r.data_file == footer.rel}
        ctx = FileContext(
            str(layout.root),
            footer.rel,
            dt,
            substeps,
            camera,
            outcomes,
            plan if footer.split == "train" else None,
            sink.cap,
            STATIC if dynamic is None else DYNAMIC,
            physics,
        )
        first = 0
        for i, n in enumerate(footer.row_groups):
            records = _task_records(in_file, ends, first, first + n) if physics else {}
            tasks.append(RowGroupTask(ctx, i, first, train_row if footer.split == "train" else 0, records))
            first += n
            if footer.split == "train":
                train_row += n

    moments: dict[str, Moments] = {}
    stats_whole = len(train) == len(layout.shards(S.DATA_DIR, "train"))
    seen: set[int] = set()
    checked_files: set[str] = set()
    current: list[RowGroupResult] = []
    for done, result in enumerate(pool.map(check_row_group, tasks)):
        sink.merge(result.sink)
        if physics is not None:
            merge_flags(dynamic.thrust, result.thrust)
            merge_flags(dynamic.debris, result.debris)
        stats_whole &= result.ok
        merge_moments(moments, result.moments)
        if current and current[-1].rel != result.rel:
            seen |= _finish_file(current, by_index, dt, substeps, sink, checked_files, dynamic)
            current = []
        current.append(result)
        if progress:
            progress("rows", done + 1, len(tasks))
    if current:
        seen |= _finish_file(current, by_index, dt, substeps, sink, checked_files, dynamic)
    if physics is not None:
        diagnose(layout.root, dynamic.thrust, dynamic.debris, dynamic.records, physics, sink)
    for r in rows:
        if r.data_file in checked_files and r.index not in seen:
            sink.add(
                C.LENGTHS,
                f"the episodes table puts {r.length} rows at {r.data_file} rows "
                f"{r.row_start}-{r.row_end}, but the file has no row of this episode",
                r.source,
                r.index,
            )
    if plan is not None:
        if stats_whole and train:
            check_stats(layout.stats, moments, train_rows, sink)
        elif not stats_whole:
            report.skipped[C.STATS] = "part of the train split could not be read"


def _finish_file(
    results: list[RowGroupResult],
    by_index: dict[int, EpisodeRow],
    dt: float,
    substeps: int,
    sink: Sink,
    checked_files: set[str],
    dynamic: _Dynamic | None = None,
) -> set[int]:
    """Seams between consecutive row groups, the file's first and last rows, and its episode runs."""
    rel = results[0].rel
    readable = [r for r in results if r.ok and r.rows]
    physics = dynamic.physics if dynamic is not None else None
    for prev, cur in zip(readable, readable[1:]):
        if prev.index + 1 == cur.index:
            check_transitions(prev.tail, cur.head, rel, sink)
            poses = pose_model(dynamic.records, physics) if physics is not None else None
            check_steps(prev.tail, cur.head, rel, dt, substeps, sink, poses)
            if physics is not None:
                merge_flags(dynamic.thrust, thrust_flags(prev.tail, cur.head, dynamic.records, physics))
    if not all(r.ok for r in results):
        return set()  # rows are missing: comparing runs with the table would only repeat the corruption
    if readable:
        check_file_edges(readable[0].head, readable[-1].tail, rel, sink)
    checked_files.add(rel)
    return check_runs(rel, [run for r in results for run in r.runs], by_index, sink)
