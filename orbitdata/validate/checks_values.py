"""Values: finiteness, ranges, rot6d, fuel, the start pose, clearance and kinematics.

Tolerances (the kinematic ones are justified in :mod:`orbitdata.validate.kinematics`):

* ``ROT6D_TOL = 1e-5``: a float32 rot6d of a true rotation has column norms and dot product
  within 1e-7 of 1 and 0 (measured max 9e-8); a scaled, sheared or swapped pair is off by O(0.1).
* ``START_TOL_M = 1e-6``: p_0 is the start position minus itself, exactly 0; 1 um allows a
  producer that rounds through float32 world coordinates.
* Actions, fuel and clearance get no tolerance: the generator writes exact zeros, validates
  actions to [0, 1] before flying them, and rounding a float64 fuel sequence that never rises to
  float32 cannot make it rise (rounding is monotone).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.state import FUEL as FUEL_SLICE
from orbitdata.state import POSITION, ROT6D, STATE_NAMES
from orbitdata.validate import checks as C
from orbitdata.validate.frames import Frames
from orbitdata.validate.kinematics import POSITION_TOL_M, ROTATION_TOL_RAD, residuals
from orbitdata.validate.report import Sink

ROT6D_TOL = 1e-5
START_TOL_M = 1e-6
FUEL = FUEL_SLICE.start  # the fuel column: (N,), not (N, 1)


def _first_bad(row: np.ndarray, names) -> str:
    i = int(np.flatnonzero(~np.isfinite(row))[0])
    return f"{names[i]} = {row[i]}"


def check_finite(fr: Frames, depth_low: np.ndarray, rel: str, sink: Sink) -> None:
    """NaN, Inf (and nulls, which arrive as NaN) in every float column."""
    columns = (
        (S.TIMESTAMP, fr.timestamp[:, None], (S.TIMESTAMP,)),
        (S.STATE, fr.state, STATE_NAMES),
        (S.ACTION, fr.action, S.ACTION_NAMES),
        (S.DEPTH_LOW, depth_low, [f"cell {i}" for i in range(S.DEPTH_LOW_DIM)]),
        (S.MIN_CLEARANCE, fr.clearance[:, None], (S.MIN_CLEARANCE,)),
    )
    for name, values, names in columns:
        bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
        sink.add_rows(
            C.FINITE,
            bad,
            lambda i: f"{name}: {_first_bad(values[i], names)} (NaN, Inf or null)",
            rel,
            fr.episode,
            fr.frame,
        )


def check_values(fr: Frames, rel: str, sink: Sink) -> None:
    """Per-row ranges: actions, rot6d, fuel, start position, clearance."""
    ep, frame = fr.episode, fr.frame
    a = fr.action
    with np.errstate(invalid="ignore"):
        out = np.flatnonzero(((a < 0) | (a > 1)).any(axis=1))
        sink.add_rows(C.ACTION, out, lambda i: f"action {np.round(a[i], 4).tolist()} leaves [0, 1]", rel, ep, frame)
        terminal = np.flatnonzero(fr.is_last & (a != 0).any(axis=1))
        sink.add_rows(
            C.ACTION,
            terminal,
            lambda i: (
                f"terminal frame has action {np.round(a[i], 4).tolist()}; "
                "nothing is applied after the last frame, so it must be all zeros"
            ),
            rel,
            ep,
            frame,
        )

        r = fr.state[:, ROT6D].reshape(-1, 3, 2)
        err = np.stack(
            [
                np.abs((r[:, :, 0] ** 2).sum(1) - 1),
                np.abs((r[:, :, 1] ** 2).sum(1) - 1),
                np.abs((r[:, :, 0] * r[:, :, 1]).sum(1)),
            ],
            axis=1,
        ).max(axis=1)
        bad = np.flatnonzero(err > ROT6D_TOL)
        sink.add_rows(
            C.ROT6D,
            bad,
            lambda i: f"rot6d columns are not orthonormal (off by {err[i]:.3g}, tolerance {ROT6D_TOL:g})",
            rel,
            ep,
            frame,
        )

        fuel = fr.state[:, FUEL]
        bad = np.flatnonzero((fuel < 0) | (fuel > 1))
        sink.add_rows(C.FUEL, bad, lambda i: f"fuel ratio {fuel[i]:.6g} leaves [0, 1]", rel, ep, frame)

        p = fr.state[:, POSITION]
        bad = np.flatnonzero((frame == 0) & (np.abs(p) > START_TOL_M).any(axis=1))
        sink.add_rows(
            C.START,
            bad,
            lambda i: (
                f"position at frame 0 is {np.round(p[i], 6).tolist()} m; states are "
                "relative to the start, so it must be 0"
            ),
            rel,
            ep,
            frame,
        )

        c = fr.clearance
        bad = np.flatnonzero(c < 0)
        sink.add_rows(C.CLEARANCE, bad, lambda i: f"min_clearance {c[i]:.4g} m is negative", rel, ep, frame)
        bad = np.flatnonzero(fr.collision & (c != 0))
        sink.add_rows(
            C.CLEARANCE,
            bad,
            lambda i: (
                f"min_clearance {c[i]:.4g} m on a collision frame, where the hull touches an obstacle (expected 0)"
            ),
            rel,
            ep,
            frame,
        )


def check_steps(
    a: Frames, b: Frames, rel: str, dt: float, substeps: int, sink: Sink, pose_model: Callable | None = None
) -> None:
    """Row a[i] -> b[i] is one control step: fuel may not rise; pose must follow v and w.

    ``pose_model(a, b) -> (position m, rotation rad)`` replaces the static body's kinematic
    residuals (:func:`orbitdata.validate.kinematics.residuals`), e.g. with the dynamic tier's.
    """
    step = (a.episode == b.episode) & (b.frame - a.frame == 1)
    ep, frame = b.episode, b.frame
    with np.errstate(invalid="ignore"):
        rise = np.flatnonzero(step & (b.state[:, FUEL] > a.state[:, FUEL]))
        sink.add_rows(
            C.FUEL,
            rise,
            lambda i: f"fuel rises from {a.state[i, FUEL]:.6g} to {b.state[i, FUEL]:.6g}; thrusters only burn it",
            rel,
            ep,
            frame,
        )
    finite = np.isfinite(a.state).all(axis=1) & np.isfinite(b.state).all(axis=1)
    idx = np.flatnonzero(step & finite & ~b.collision)  # contact impulses make the collision step unpredictable
    if not len(idx):
        return
    with np.errstate(invalid="ignore", divide="ignore"):
        if pose_model is None:
            pos, rot = residuals(a.state[idx], b.state[idx], dt, substeps)
        else:
            pos, rot = pose_model(a.take(idx), b.take(idx))
    bad = np.flatnonzero(~(pos <= POSITION_TOL_M))
    sink.add_rows(
        C.KIN_POSITION,
        bad,
        lambda k: (
            f"step {frame[idx][k] - 1}->{frame[idx][k]}: position ends "
            f"{1000 * pos[k]:.1f} mm from where the velocities put it after {dt:g} s (tolerance "
            f"{1000 * POSITION_TOL_M:g} mm)"
        ),
        rel,
        ep[idx],
        frame[idx],
    )
    bad = np.flatnonzero(~(rot <= ROTATION_TOL_RAD))
    sink.add_rows(
        C.KIN_ROTATION,
        bad,
        lambda k: (
            f"step {frame[idx][k] - 1}->{frame[idx][k]}: attitude ends "
            f"{rot[k]:.3g} rad from where the angular velocities turn it in {dt:g} s (tolerance "
            f"{ROTATION_TOL_RAD:g} rad)"
        ),
        rel,
        ep[idx],
        frame[idx],
    )


def _all_finite(value) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_all_finite(v) for v in value.values())
    if isinstance(value, list):
        return all(_all_finite(v) for v in value)
    return True


def check_episode_floats(table: pa.Table, rel: str, sink: Sink) -> None:
    """NaN or Inf in the episodes table (goal, obstacles, velocities, lighting, planner)."""
    episodes = table.column(S.EPISODE_INDEX).to_pylist()
    for name in table.column_names:
        if not pa.types.is_floating(table.schema.field(name).type) and not pa.types.is_nested(
            table.schema.field(name).type
        ):
            continue
        for i, value in enumerate(table.column(name).to_pylist()):
            if not _all_finite(value):
                sink.add(C.FINITE, f"episodes column {name!r} holds NaN or Inf: {value}", rel, episodes[i])
