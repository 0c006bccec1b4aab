"""The dynamic tier's physics, row by row: thrust to acceleration, debris poses, and the tier's kinematics.

Workers run these on each row group (and the driver on the seams between row groups) against
the episode record (:mod:`~orbitdata.validate.dynamic_record`). They only flag the episodes
whose steps or poses are off: the driver then reads each flagged episode whole and names what
is wrong (:mod:`~orbitdata.validate.diagnose_dynamic`), one line per episode.

Tolerances. The model is the simulator's own integrator on the recorded body
(:mod:`~orbitdata.sim.rigid_body`; the residuals against it in :mod:`~orbitdata.validate.residuals`), so what is left is the float32 rounding of the states
(about 1e-7 of |v|, |w| and of the attitude) and of the record:

* ``VELOCITY_TOL = 1e-5 m/s``: ten times the rounding of a 10 m/s velocity. One thruster's
  thrust changes a step's velocity by 0.15 m/s per unit of command, and the Clohessy-Wiltshire
  Coriolis term by ``2 n |v| dt``, about 9e-5 m/s per m/s of speed: a CW flag that is wrong shows
  on every step faster than 0.2 m/s.
* ``ANGULAR_TOL = 1e-4 rad/s``: rounding of w and of the gyroscopic term at tens of rad/s; one
  thruster's torque changes w by several rad/s per unit of command in a step.
* ``FUEL_TOL = 1e-6``: the float32 fuel ratio near 1 rounds to 6e-8; a step burns 9e-4 of the
  tank per unit of thrust, so a stuck thruster's few percent show.
* ``POSE_TOL_M = 1e-4 m`` and ``POSE_TOL_RAD = 1e-4 rad``: a pose recomputed from the float32
  record of t = 0 and of the motion differs from the float32 pose by the rounding of metres
  and of ``w t`` over a 12 s episode (micrometres, microradians). The CW terms move a piece
  drifting at 0.1 m/s by ``n |v| t^2``, 1e-4 m after a second.
* The step that ends in a collision is left out, as in the static kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.sim.config import CubeSatConfig
from orbitdata.sim.rigid_body import StepBody
from orbitdata.validate import checks as C
from orbitdata.validate.dynamic_record import EpisodeRecord, step_body
from orbitdata.validate.frames import Frames
from orbitdata.validate.report import Sink
from orbitdata.validate.residuals import ThrustResiduals, pose_residuals, thrust_residuals

VELOCITY_TOL = 1e-5
ANGULAR_TOL = 1e-4
FUEL_TOL = 1e-6
POSE_TOL_M = 1e-4
POSE_TOL_RAD = 1e-4


@dataclass(frozen=True)
class Physics:
    """The simulator settings the dynamic checks need (from meta/info.json's config)."""

    cubesat: CubeSatConfig
    dt: float
    substeps: int


@dataclass
class Flag:
    """An episode with steps or poses off its record, as one block of rows saw it."""

    first: int  # first frame off (of a step: the frame it starts from)
    count: int  # steps (thrust) or obstacle poses (debris) off

    def merge(self, other: "Flag") -> "Flag":
        return Flag(min(self.first, other.first), self.count + other.count)


def merge_flags(into: dict[int, Flag], flags: dict[int, Flag]) -> None:
    for episode, flag in flags.items():
        into[episode] = into[episode].merge(flag) if episode in into else flag


def _flags(episodes: np.ndarray, frames: np.ndarray) -> dict[int, Flag]:
    out: dict[int, Flag] = {}
    for e, f in zip(episodes.tolist(), frames.tolist()):
        merge_flags(out, {e: Flag(f, 1)})
    return out


# ---- thrust to acceleration ---------------------------------------------------------------
def thrust_fits(res: ThrustResiduals) -> np.ndarray:
    """Steps whose end is where the thrust takes them (NaN never fits)."""
    return (res.velocity <= VELOCITY_TOL) & (res.angular_velocity <= ANGULAR_TOL) & (res.fuel <= FUEL_TOL)


def steps_of(a: Frames, b: Frames, records: dict[int, EpisodeRecord]) -> tuple[np.ndarray, StepBody]:
    """Indices of the pairs a[i] -> b[i] that are one checkable step of an episode with a record,
    and that record as arrays."""
    body, known = step_body(records, a.episode)
    finite = np.isfinite(a.state).all(axis=1) & np.isfinite(b.state).all(axis=1) & np.isfinite(a.action).all(axis=1)
    step = (a.episode == b.episode) & (b.frame - a.frame == 1) & ~b.collision & finite & known
    idx = np.flatnonzero(step)
    return idx, body.take(idx)


def step_thrust(a: Frames, b: Frames, idx: np.ndarray, body: StepBody, physics: Physics) -> ThrustResiduals:
    return thrust_residuals(
        a.state[idx], b.state[idx], a.action[idx], a.frame[idx], body, physics.cubesat, physics.dt, physics.substeps
    )


def thrust_flags(a: Frames, b: Frames, records: dict[int, EpisodeRecord], physics: Physics) -> dict[int, Flag]:
    """Episodes with a step a[i] -> b[i] that the recorded thrust, fault and body do not explain."""
    idx, body = steps_of(a, b, records)
    if not len(idx):
        return {}
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~thrust_fits(step_thrust(a, b, idx, body, physics))
    return _flags(a.episode[idx[bad]], a.frame[idx[bad]])  # a step is named by the frame it starts from


def pose_model(records: dict[int, EpisodeRecord], physics: Physics) -> Callable[[Frames, Frames], tuple]:
    """The tier's kinematic residuals of steps a -> b (see :func:`residuals.pose_residuals`): the
    recorded body with its centre of mass offset and its anisotropic inertia; 0 for a step whose
    episode has no well-formed record (``dynamics.record`` reports it)."""

    def residuals(a: Frames, b: Frames) -> tuple[np.ndarray, np.ndarray]:
        body, known = step_body(records, a.episode)
        pos, rot = np.zeros(len(a)), np.zeros(len(a))
        if known.any():
            k = np.flatnonzero(known)
            pos[k], rot[k] = pose_residuals(
                a.state[k], b.state[k], body.take(k), physics.cubesat, physics.dt, physics.substeps
            )
        return pos, rot

    return residuals


# ---- debris poses -------------------------------------------------------------------------
@dataclass
class Poses:
    """The privileged.obstacle_poses of a block of rows."""

    offsets: np.ndarray  # (N + 1,) row i's poses are values[offsets[i]:offsets[i + 1]]
    values: np.ndarray  # (M, 7) float64: centre (m) and quat (w, x, y, z); NaN where null
    valid: np.ndarray  # (N,) the row's list is not null

    @classmethod
    def from_column(cls, column: pa.ChunkedArray) -> "Poses":
        arr = column.combine_chunks()
        offsets = np.asarray(arr.offsets, dtype=np.int64)
        inner = arr.values
        flat = inner.values.slice(inner.offset * 7, len(inner) * 7)
        values = flat.to_numpy(zero_copy_only=False).astype(np.float64).reshape(len(inner), 7)
        if inner.null_count:
            values[~np.asarray(inner.is_valid())] = np.nan
        valid = np.asarray(arr.is_valid()) if arr.null_count else np.ones(len(arr), bool)
        return cls(offsets, values, valid)

    def counts(self) -> np.ndarray:
        return np.diff(self.offsets)

    def rows(self, index: np.ndarray, n: int) -> np.ndarray:
        """(len(index), n, 7) poses of rows that each hold n."""
        take = self.offsets[index][:, None] + np.arange(n)[None, :]
        return self.values[take]


def pose_errors(recorded: np.ndarray, expected: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m) and turn (rad) between poses (..., 7)."""
    dist = np.linalg.norm(recorded[..., :3] - expected[..., :3], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = recorded[..., 3:] / np.linalg.norm(recorded[..., 3:], axis=-1, keepdims=True)
        e = expected[..., 3:]
        e = np.where(np.sum(q * e, axis=-1, keepdims=True) < 0, -e, e)  # q and -q are one attitude
        # |q - e| = 2 sin(angle / 4): exact near 0, where arccos of the dot product loses half the digits
        chord = np.linalg.norm(q - e, axis=-1)
    return dist, 4.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0))


def pose_fits(dist: np.ndarray, turn: np.ndarray) -> np.ndarray:
    return (dist <= POSE_TOL_M) & (turn <= POSE_TOL_RAD)


def expected_poses(record: EpisodeRecord, frames: np.ndarray, dt: float, flip_cw: bool = False) -> np.ndarray:
    """(T, N, 7) where the record puts the obstacles at ``frames``; ``flip_cw``: with the cw flag
    the other way (the hypothesis that the flag is wrong)."""
    scn = record.scenario
    if flip_cw:
        scn = replace(scn, dynamics=replace(scn.dynamics, cw=not scn.dynamics.cw))
    return scn.obstacle_poses(frames.astype(np.float64) * dt)


def debris_flags(
    fr: Frames, poses: Poses, records: dict[int, EpisodeRecord], dt: float, rel: str, sink: Sink
) -> dict[int, Flag]:
    """Episodes with an obstacle pose off its recorded motion. A frame whose pose count is not the
    episode's obstacle count is reported here (``dynamics.record``, once per episode and block)."""
    out: dict[int, Flag] = {}
    counts = poses.counts()
    for e in np.unique(fr.episode):
        record = records.get(int(e))
        if record is None:
            continue
        rows = np.flatnonzero((fr.episode == e) & poses.valid & (fr.frame >= 0))
        n = len(record.scenario.obstacles)
        wrong = rows[counts[rows] != n]
        if len(wrong):
            sink.add(
                C.DYN_RECORD,
                f"{len(wrong)} frame(s) have {counts[wrong[0]]} obstacle poses, the episode has {n} obstacles",
                rel,
                int(e),
                int(fr.frame[wrong[0]]),
            )
        rows = rows[counts[rows] == n]
        if not len(rows) or n == 0:
            continue
        dist, turn = pose_errors(poses.rows(rows, n), expected_poses(record, fr.frame[rows], dt))
        off = ~pose_fits(dist, turn)  # (T, n)
        if off.any():
            merge_flags(out, {int(e): Flag(int(fr.frame[rows][off.any(axis=1)].min()), int(off.sum()))})
    return out


def read_poses(table: pa.Table) -> Poses | None:
    return Poses.from_column(table.column(S.OBSTACLE_POSES)) if S.OBSTACLE_POSES in table.column_names else None
