"""Turn a flown episode into Arrow rows of the steps and episodes tables of its tier.

A dynamic-tier episode adds each frame's obstacle poses to its steps and its
:class:`~orbitdata.scenario.dynamics.Dynamics` record to its episode row (the struct fields are
the records' own); a static one writes exactly the static columns.
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.fly.rollout import EpisodeResult
from orbitdata.scenario.config import DYNAMIC, STATIC


def _fixed_list(values: np.ndarray, width: int) -> pa.FixedSizeListArray:
    flat = pa.array(np.ascontiguousarray(values, dtype=np.float32).reshape(-1), type=pa.float32())
    return pa.FixedSizeListArray.from_arrays(flat, width)


def _images(blobs: list[bytes]) -> pa.StructArray:
    return pa.StructArray.from_arrays(
        [pa.array(blobs, type=pa.binary()), pa.nulls(len(blobs), type=pa.string())], names=["bytes", "path"]
    )


def _poses(poses: np.ndarray) -> pa.ListArray:
    """(L, N, 7) -> one list of N fixed lists of 7 float32 per frame."""
    frames, count = poses.shape[:2]
    inner = _fixed_list(poses.reshape(-1, 7), 7)
    offsets = pa.array(np.arange(frames + 1, dtype=np.int32) * count, type=pa.int32())
    return pa.ListArray.from_arrays(offsets, inner, type=S.step_schema(DYNAMIC).field(S.OBSTACLE_POSES).type)


def _check_tier(result: EpisodeResult, episode_index: int, tier: str) -> bool:
    """Whether the episode carries the dynamic tier's record; raises if it is not ``tier``'s."""
    moving = result.scenario.dynamics is not None
    if moving != (tier != STATIC):
        raise ValueError(
            f"episode {episode_index} is {'a dynamic' if moving else 'a static'} scenario, but the dataset's tier is "
            f"{tier!r}"
        )
    if moving and result.obstacle_poses is None:
        raise ValueError(f"episode {episode_index}: a dynamic scenario flown without its obstacle poses recorded")
    return moving


def steps_table(
    result: EpisodeResult, episode_index: int, rgb: list[bytes], depth: list[bytes], tier: str = STATIC
) -> pa.Table:
    moving = _check_tier(result, episode_index, tier)
    n = result.length
    if len(rgb) != n or len(depth) != n:
        raise AssertionError(f"episode {episode_index}: {n} frames but {len(rgb)} RGB / {len(depth)} depth images")
    frames = np.arange(n, dtype=np.int32)
    is_last = np.zeros(n, dtype=bool)
    is_last[-1] = True
    columns = {
        S.EPISODE_INDEX: pa.array(np.full(n, episode_index, np.int32)),
        S.FRAME_INDEX: pa.array(frames),
        S.TIMESTAMP: pa.array((frames * np.float32(S.DT)).astype(np.float32)),
        S.IMAGE: _images(rgb),
        S.DEPTH: _images(depth),
        S.DEPTH_LOW: _fixed_list(result.depth_low, S.DEPTH_LOW_DIM),
        S.STATE: _fixed_list(result.states, S.STATE_DIM),
        S.ACTION: _fixed_list(result.actions, S.ACTION_DIM),
        S.COLLISION: pa.array(result.collision),
        S.SUCCESS: pa.array(result.success),
        S.IS_LAST: pa.array(is_last),
        S.MIN_CLEARANCE: pa.array(result.min_clearance.astype(np.float32)),
    }
    if moving:
        columns[S.OBSTACLE_POSES] = _poses(result.obstacle_poses)
    return pa.table(columns, schema=S.step_schema(tier))


def episode_row(result: EpisodeResult, episode_index: int, split: str, tier: str = STATIC) -> dict:
    moving = _check_tier(result, episode_index, tier)
    scn = result.scenario
    planner = result.pilot_info.get("planner") or {}
    row = {
        S.EPISODE_INDEX: episode_index,
        S.SPLIT: split,
        S.LEVEL: result.pilot,
        S.SEED: result.seed,
        S.LENGTH: result.length,
        S.OUTCOME: result.outcome,
        S.N_OBSTACLES: len(scn.obstacles),
        S.OBSTACLES: [asdict(o) for o in scn.obstacles],  # the struct's fields are Obstacle's
        S.GOAL: list(scn.goal),
        S.GOAL_RADIUS: scn.goal_radius,
        S.INITIAL_VELOCITY: list(scn.initial_velocity),
        S.INITIAL_QUAT: list(scn.initial_quat),
        S.LIGHTING: asdict(scn.lighting),
        S.PLANNER: {
            "solved": bool(planner.get("solved", False)),
            "iterations": int(planner.get("iterations", 0)),
            "path_length": float(planner.get("path_length", 0.0)),
        },
        S.DATA_FILE: "",
        S.ROW_START: 0,
        S.ROW_END: 0,
    }
    if moving:  # the structs' fields are the records' own
        row |= {S.DYNAMICS_COLUMNS[k]: v for k, v in asdict(scn.dynamics).items()}
    return row


def episodes_table(rows: list[dict], tier: str = STATIC) -> pa.Table:
    return pa.Table.from_pylist(rows, schema=S.episode_schema(tier))
