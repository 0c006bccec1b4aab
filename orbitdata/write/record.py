"""Turn a flown episode into Arrow rows of the steps and episodes tables."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.fly.rollout import EpisodeResult


def _fixed_list(values: np.ndarray, width: int) -> pa.FixedSizeListArray:
    flat = pa.array(np.ascontiguousarray(values, dtype=np.float32).reshape(-1), type=pa.float32())
    return pa.FixedSizeListArray.from_arrays(flat, width)


def _images(blobs: list[bytes]) -> pa.StructArray:
    return pa.StructArray.from_arrays(
        [pa.array(blobs, type=pa.binary()), pa.nulls(len(blobs), type=pa.string())], names=["bytes", "path"]
    )


def steps_table(result: EpisodeResult, episode_index: int, rgb: list[bytes], depth: list[bytes]) -> pa.Table:
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
    return pa.table(columns, schema=S.STEP_SCHEMA)


def episode_row(result: EpisodeResult, episode_index: int, split: str) -> dict:
    scn = result.scenario
    planner = result.pilot_info.get("planner") or {}
    return {
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


def episodes_table(rows: list[dict]) -> pa.Table:
    return pa.Table.from_pylist(rows, schema=S.EPISODE_SCHEMA)
