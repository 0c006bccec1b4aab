"""Episodes: the episodes table on its own (quick), and the steps rows against it (full).

Row checks work on a block of rows and on the transitions between consecutive rows, so the same
functions check the inside of a row group (in a worker) and the seams between row groups (in
the driver, on the last row of one and the first of the next).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.scenario.config import STATIC
from orbitdata.validate import checks as C
from orbitdata.validate.frames import Frames
from orbitdata.validate.report import Sink

# float32 holds t = 12 s to within 1e-6 s; 1e-5 s is ten ulps there and far below the 40 ms grid.
TIMESTAMP_TOL_S = 1e-5


@dataclass(frozen=True)
class EpisodeRow:
    index: int
    split: str
    level: str
    seed: int
    length: int
    outcome: str
    n_obstacles: int
    n_obstacle_rows: int
    data_file: str
    row_start: int
    row_end: int
    source: str  # the episodes shard it came from


def episode_rows(table: pa.Table, source: str) -> list[EpisodeRow]:
    cols = {
        name: table.column(name).to_pylist()
        for name in (
            S.EPISODE_INDEX,
            S.SPLIT,
            S.LEVEL,
            S.SEED,
            S.LENGTH,
            S.OUTCOME,
            S.N_OBSTACLES,
            S.DATA_FILE,
            S.ROW_START,
            S.ROW_END,
        )
    }
    n_obs = [len(x) if x is not None else 0 for x in table.column(S.OBSTACLES).to_pylist()]
    return [
        EpisodeRow(
            cols[S.EPISODE_INDEX][i],
            cols[S.SPLIT][i],
            cols[S.LEVEL][i],
            cols[S.SEED][i],
            cols[S.LENGTH][i],
            cols[S.OUTCOME][i],
            cols[S.N_OBSTACLES][i],
            n_obs[i],
            cols[S.DATA_FILE][i],
            cols[S.ROW_START][i],
            cols[S.ROW_END][i],
            source,
        )
        for i in range(table.num_rows)
    ]


# ---- the episodes table (quick) -------------------------------------------------------------
def check_table(
    rows: list[EpisodeRow], split_of_file: dict[str, str], max_steps: int | None, sink: Sink, tier: str = STATIC
) -> None:
    """Field validity, duplicates and split hygiene of the episodes table (outcomes: the ``tier``'s)."""
    outcomes = S.outcomes(tier)
    for r in rows:
        where = dict(file=r.source, episode=r.index)
        if None in (r.index, r.split, r.level, r.length, r.outcome, r.data_file, r.row_start, r.row_end):
            sink.add(C.TABLE, "a required field is null", **where)
            continue
        if r.split != split_of_file[r.source]:
            sink.add(C.TABLE, f"split is {r.split!r} but the row is in the {split_of_file[r.source]} shard", **where)
        if r.level not in S.LEVELS:
            sink.add(C.TABLE, f"level {r.level!r} is not one of {S.LEVELS}", **where)
        if r.outcome not in outcomes:
            sink.add(C.TABLE, f"outcome {r.outcome!r} is not one of {outcomes}", **where)
        if r.length < 1 or (max_steps is not None and r.length > max_steps):
            sink.add(C.TABLE, f"length {r.length} is outside [1, {max_steps}] (sim.max_steps)", **where)
        if r.n_obstacles != r.n_obstacle_rows:
            sink.add(C.TABLE, f"n_obstacles is {r.n_obstacles} but {r.n_obstacle_rows} obstacles are listed", **where)
        if r.row_end - r.row_start != r.length:
            sink.add(
                C.LENGTHS,
                f"row range {r.row_start}-{r.row_end} holds {r.row_end - r.row_start} rows, length says {r.length}",
                **where,
            )
    by_index: dict[int, list[EpisodeRow]] = {}
    for r in rows:
        by_index.setdefault(r.index, []).append(r)
    for index, same in sorted(by_index.items(), key=lambda kv: (kv[0] is None, kv[0] or 0)):
        if len(same) > 1:
            splits = sorted({r.split for r in same})
            check = C.LEAK if len(splits) > 1 else C.DUPLICATES
            what = "in both splits" if len(splits) > 1 else f"{len(same)} times"
            sink.add(
                check, f"episode_index appears {what} (in {', '.join(sorted({r.source for r in same}))})", episode=index
            )
    seeds: dict[int, set[str]] = {}
    for r in rows:
        seeds.setdefault(r.seed, set()).add(r.split)
    for seed, splits in sorted(seeds.items(), key=lambda kv: kv[0] or 0):
        if len(splits) > 1:
            eps = sorted(r.index for r in rows if r.seed == seed)
            sink.add(C.LEAK, f"seed {seed} is used in both splits (episodes {eps}): the test split is not held out")
    for r in rows:
        m = S.SHARD_RE.match(r.data_file or "")
        if m and m.group(2) != r.split:
            sink.add(C.LEAK, f"a {r.split} episode whose rows are in {r.data_file}", file=r.source, episode=r.index)


def check_row_ranges(rows: list[EpisodeRow], file_rows: dict[str, int], sink: Sink) -> None:
    """Per data file: the episodes' row ranges must tile [0, num_rows) exactly."""
    by_file: dict[str, list[EpisodeRow]] = {}
    for r in rows:
        if r.data_file not in file_rows:
            sink.add(
                C.LENGTHS,
                f"data_file {r.data_file!r} is not a readable data shard of this dataset",
                file=r.source,
                episode=r.index,
            )
            continue
        by_file.setdefault(r.data_file, []).append(r)
    for rel, n in sorted(file_rows.items()):
        cursor = 0
        for r in sorted(by_file.get(rel, []), key=lambda r: (r.row_start, r.index)):
            if r.row_start != cursor:
                what = "rows not covered by any episode" if r.row_start > cursor else "overlapping row ranges"
                sink.add(
                    C.LENGTHS,
                    f"{what} at rows {min(cursor, r.row_start)}-{max(cursor, r.row_start)}",
                    file=rel,
                    episode=r.index,
                )
            cursor = max(cursor, r.row_end)
        if cursor != n:
            sink.add(C.LENGTHS, f"the episodes table covers rows 0-{cursor} but the file has {n} rows", file=rel)


# ---- steps rows (full) --------------------------------------------------------------------
def check_rows(fr: Frames, rel: str, dt: float, outcomes: dict[int, str], sink: Sink) -> None:
    """Per-row checks: timestamps on the grid, event flags where (and as) they belong."""
    ep, frame = fr.episode, fr.frame
    expected_t = frame * np.float64(np.float32(dt))
    with np.errstate(invalid="ignore"):
        off = np.flatnonzero((frame >= 0) & ~(np.abs(fr.timestamp - expected_t) <= TIMESTAMP_TOL_S))
    sink.add_rows(
        C.TIMESTAMPS,
        off,
        lambda i: f"timestamp {fr.timestamp[i]:.6g} s, expected {expected_t[i]:.6g} s (frame {frame[i]} x {dt:g} s)",
        rel,
        ep,
        frame,
    )
    early = np.flatnonzero((fr.collision | fr.success) & ~fr.is_last)
    sink.add_rows(
        C.EVENTS,
        early,
        lambda i: (
            f"{'collision' if fr.collision[i] else 'success'} on a frame that is "
            "not the last: the episode must end at its first event"
        ),
        rel,
        ep,
        frame,
    )
    for i in np.flatnonzero(fr.is_last):
        outcome = outcomes.get(int(ep[i]))
        if outcome is None:
            continue  # no episodes-table row: reported by episodes.lengths
        if bool(fr.collision[i]) != (outcome == "collision") or bool(fr.success[i]) != (outcome == "success"):
            sink.add(
                C.EVENTS,
                f"last frame has collision={bool(fr.collision[i])} success={bool(fr.success[i])}, "
                f"but the episodes table says outcome {outcome!r}",
                rel,
                int(ep[i]),
                int(frame[i]),
            )


def check_transitions(a: Frames, b: Frames, rel: str, sink: Sink) -> None:
    """Row a[i] is directly followed by row b[i] in the file."""
    same = a.episode == b.episode
    step = b.frame - a.frame
    dup = np.flatnonzero(same & (step == 0))
    sink.add_rows(
        C.FRAMES,
        dup,
        lambda i: f"frame {b.frame[i]} appears twice (rows {a.row[i]} and {b.row[i]})",
        rel,
        b.episode,
        b.frame,
    )
    gap = np.flatnonzero(same & (step > 1))
    sink.add_rows(
        C.FRAMES,
        gap,
        lambda i: (
            f"frames {a.frame[i] + 1}-{b.frame[i] - 1} are missing (frame {a.frame[i]} is followed by {b.frame[i]})"
        ),
        rel,
        b.episode,
        b.frame,
    )
    back = np.flatnonzero(same & (step < 0))
    sink.add_rows(
        C.FRAMES,
        back,
        lambda i: f"frame {b.frame[i]} follows frame {a.frame[i]}: rows are not ordered by frame_index",
        rel,
        b.episode,
        b.frame,
    )
    new = ~same
    start = np.flatnonzero(new & (b.frame != 0))
    sink.add_rows(
        C.FRAMES,
        start,
        lambda i: f"episode starts at frame {b.frame[i]}, not 0 (row {b.row[i]})",
        rel,
        b.episode,
        b.frame,
    )
    order = np.flatnonzero(new & (b.episode < a.episode))
    sink.add_rows(
        C.FRAMES,
        order,
        lambda i: f"episode {b.episode[i]} follows episode {a.episode[i]}: rows are not ordered by episode_index",
        rel,
        b.episode,
        b.frame,
    )
    early = np.flatnonzero(same & a.is_last)
    sink.add_rows(C.LENGTHS, early, lambda i: f"is_last is set but frame {b.frame[i]} follows", rel, a.episode, a.frame)
    unmarked = np.flatnonzero(new & ~a.is_last)
    sink.add_rows(
        C.LENGTHS, unmarked, lambda i: "the episode's last row does not have is_last set", rel, a.episode, a.frame
    )


def check_file_edges(first: Frames, last: Frames, rel: str, sink: Sink) -> None:
    if len(first) and first.frame[0] != 0:
        sink.add(
            C.FRAMES,
            f"the file's first row is frame {first.frame[0]}, not 0",
            rel,
            int(first.episode[0]),
            int(first.frame[0]),
        )
    if len(last) and not last.is_last[0]:
        sink.add(
            C.LENGTHS, "the file's last row does not have is_last set", rel, int(last.episode[0]), int(last.frame[0])
        )


def runs(fr: Frames) -> list[tuple[int, int, int]]:
    """Maximal runs of one episode: (episode, first row, end row)."""
    if not len(fr):
        return []
    cut = np.flatnonzero(fr.episode[1:] != fr.episode[:-1]) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut, [len(fr)]])
    return [(int(fr.episode[s]), int(fr.row[s]), int(fr.row[e - 1]) + 1) for s, e in zip(starts, ends)]


def check_runs(rel: str, file_runs: list[tuple[int, int, int]], table: dict[int, EpisodeRow], sink: Sink) -> set[int]:
    """Compare where each episode's rows are in one file with the episodes table. Returns its episodes."""
    merged: list[list[int]] = []
    for ep, start, end in file_runs:
        if merged and merged[-1][0] == ep and merged[-1][2] == start:
            merged[-1][2] = end
        else:
            merged.append([ep, start, end])
    by_ep: dict[int, list[tuple[int, int]]] = {}
    for ep, start, end in merged:
        by_ep.setdefault(ep, []).append((start, end))
    for ep, spans in by_ep.items():
        if len(spans) > 1:
            where = ", ".join(f"{s}-{e}" for s, e in spans[:4])
            sink.add(
                C.FRAMES,
                f"rows are split into {len(spans)} separate runs (rows {where}): not ordered by episode",
                rel,
                ep,
            )
            continue
        start, end = spans[0]
        row = table.get(ep)
        if row is None:
            sink.add(C.LENGTHS, f"{end - start} rows (rows {start}-{end}) but no row in the episodes table", rel, ep)
        elif row.data_file != rel:
            sink.add(C.LENGTHS, f"rows are in this file, the episodes table says {row.data_file}", rel, ep)
        elif (start, end) != (row.row_start, row.row_end):
            sink.add(
                C.LENGTHS,
                f"{end - start} frames at rows {start}-{end}; the episodes table says length "
                f"{row.length} at rows {row.row_start}-{row.row_end}",
                rel,
                ep,
            )
    return set(by_ep)
