"""The unit of work of a full validation: every check on one row group of one data shard.

A task reads one row group (bounded memory whatever the dataset size), runs the row, step,
value and image checks on it, and returns its findings plus what the driver needs to finish
the job: the first and last rows (to check the seams between row groups), the episode runs
(to compare with the episodes table) and its share of the train statistics.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyarrow.parquet as pq

from orbitdata import schema as S
from orbitdata.codecs import stats_width
from orbitdata.scenario.config import STATIC
from orbitdata.validate import checks as C
from orbitdata.validate.checks_consistency import Moments, StatsPlan
from orbitdata.validate.checks_dynamic import Physics, debris_flags, pose_model, read_poses, thrust_flags
from orbitdata.validate.checks_episodes import check_rows, check_transitions, runs
from orbitdata.validate.checks_images import Camera, check_images
from orbitdata.validate.checks_values import check_finite, check_steps, check_values
from orbitdata.validate.frames import Frames, fixed_list, null_columns
from orbitdata.validate.report import Sink


@dataclass(frozen=True)
class FileContext:
    """What every row-group task of one data shard needs to know."""

    root: str
    rel: str
    dt: float  # seconds per step
    substeps: int  # physics substeps per step (the kinematic model)
    camera: Camera | None
    outcomes: dict  # episode_index -> outcome, for the episodes the table puts in this file
    stats: StatsPlan | None  # set for train shards: recompute their share of meta/stats.json
    cap: int
    tier: str = STATIC  # the dynamic tier's depth camera drops pixels that depth_low keeps
    physics: Physics | None = None  # the dynamic tier: check its physics against the episode record


@dataclass(frozen=True)
class RowGroupTask:
    ctx: FileContext
    index: int  # row group number
    first_row: int  # its first row within the file
    train_row: int  # its first row within the whole train split (for the stats sampling)
    records: dict = field(default_factory=dict)  # the dynamic tier: episode -> EpisodeRecord of its rows


@dataclass
class RowGroupResult:
    rel: str
    index: int
    sink: Sink
    ok: bool = True  # False: the row group did not decode
    rows: int = 0
    head: Frames | None = None
    tail: Frames | None = None
    runs: list = field(default_factory=list)
    moments: dict = field(default_factory=dict)  # feature -> Moments (train shards only)
    thrust: dict = field(default_factory=dict)  # the dynamic tier: episode -> Flag of steps off the thrust
    debris: dict = field(default_factory=dict)  # ... and of obstacle poses off their motion


def init_worker() -> None:
    """Process-pool initializer: one core per worker, so N workers use N cores, not N^2 threads."""
    import cv2
    import pyarrow as pa

    cv2.setNumThreads(1)
    pa.set_cpu_count(1)


def check_row_group(task: RowGroupTask) -> RowGroupResult:
    ctx = task.ctx
    sink = Sink(ctx.cap)
    result = RowGroupResult(ctx.rel, task.index, sink)
    try:
        table = pq.ParquetFile(f"{ctx.root}/{ctx.rel}").read_row_group(task.index, use_threads=False)
    except Exception as exc:  # bad pages surface as ArrowInvalid, OSError, ...
        sink.add(
            C.CORRUPT,
            f"row group {task.index} (rows {task.first_row}+) does not decode "
            f"({type(exc).__name__}: {str(exc)[:160]}); download the file again or regenerate it",
            ctx.rel,
        )
        result.ok = False
        return result
    fr = Frames.from_table(table, task.first_row)
    depth_low = fixed_list(table.column(S.DEPTH_LOW), S.DEPTH_LOW_DIM)
    for name, rows in null_columns(table).items():
        sink.add_rows(C.FINITE, rows, lambda i, name=name: f"{name} is null", ctx.rel, fr.episode, fr.frame)

    check_rows(fr, ctx.rel, ctx.dt, ctx.outcomes, sink)
    check_finite(fr, depth_low, ctx.rel, sink)
    check_values(fr, ctx.rel, sink)
    dynamic = ctx.physics is not None
    poses = pose_model(task.records, ctx.physics) if dynamic else None
    if len(fr) > 1:
        a, b = fr.take(slice(0, -1)), fr.take(slice(1, None))
        check_transitions(a, b, ctx.rel, sink)
        check_steps(a, b, ctx.rel, ctx.dt, ctx.substeps, sink, poses)
        if dynamic:
            result.thrust = thrust_flags(a, b, task.records, ctx.physics)
    if dynamic and (obstacle_poses := read_poses(table)) is not None:
        result.debris = debris_flags(fr, obstacle_poses, task.records, ctx.dt, ctx.rel, sink)

    global_rows = np.arange(task.train_row, task.train_row + len(fr))
    keep_rgb = np.flatnonzero(global_rows % ctx.stats.image_stride == 0) if ctx.stats else np.empty(0, int)
    rgb = check_images(table, fr, depth_low, ctx.camera, ctx.rel, sink, keep_rgb, dropout=ctx.tier != STATIC)
    if ctx.stats:
        result.moments = _moments(fr, depth_low, rgb, ctx.stats)
    result.rows = len(fr)
    result.head, result.tail = fr.take(slice(0, 1)), fr.take(slice(-1, None))
    result.runs = runs(fr)
    return result


def _moments(fr: Frames, depth_low: np.ndarray, rgb: dict, plan: StatsPlan) -> dict:
    """This row group's share of the train statistics (see checks_consistency)."""
    columns = {
        S.STATE: fr.state,
        S.ACTION: fr.action,
        S.DEPTH_LOW: depth_low,
        S.MIN_CLEARANCE: fr.clearance[:, None],
        S.TIMESTAMP: fr.timestamp[:, None],
    }
    out = {}
    for name, x in columns.items():
        assert x.shape[1] == stats_width(name), name
        m = Moments()
        m.update(x, plan.quantiles.get(name))
        out[name] = m
    if rgb:
        hist = np.zeros((3, 256), np.int64)  # per-channel value counts: every image statistic follows
        for pixels in rgb.values():
            for c in range(3):
                hist[c] += np.bincount(pixels[..., c].reshape(-1), minlength=256)
        out[S.IMAGE] = Moments.from_histogram(hist, plan.quantiles.get(S.IMAGE))
    return out
