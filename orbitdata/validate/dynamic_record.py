"""The dynamic tier's episode record as the validator reads it from the episodes table.

Each row's dynamic columns (``debris_motion``, ``cw``, ``mean_motion``, ``body``, ``fault``,
``sensing``) and its obstacles become a :class:`~orbitdata.scenario.spec.Scenario` with its
:class:`~orbitdata.scenario.dynamics.Dynamics`, built by the same records the simulator flies, so
a field the records refuse (an unknown fault kind, a thruster out of range, one motion short of
the obstacles) is reported by ``dynamics.record`` and that episode's physics is not checked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.scenario.dynamics import BodyParameters, DebrisMotion, Dynamics, Sensing, ThrusterFault
from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.sim.rigid_body import StepBody
from orbitdata.validate import checks as C
from orbitdata.validate.report import Sink

DYNAMIC_COLUMNS = (S.DEBRIS_MOTION, S.CW, S.MEAN_MOTION, S.BODY, S.FAULT, S.SENSING)


@dataclass(frozen=True)
class EpisodeRecord:
    """One episode's world as recorded: its obstacles at t = 0 and its dynamics."""

    index: int
    data_file: str
    row_start: int
    row_end: int
    scenario: Scenario

    @property
    def dynamics(self) -> Dynamics:
        return self.scenario.dynamics


def _tuple(value):
    return tuple(float(x) for x in value) if value is not None else None


def _finite(*values: float) -> bool:
    return all(v is not None and math.isfinite(v) for v in values)


def _record(row: dict) -> Scenario:
    """The row's scenario; raises ValueError (or TypeError) saying what is malformed."""
    missing = [name for name in DYNAMIC_COLUMNS if row.get(name) is None]
    if missing:
        raise ValueError(f"{', '.join(missing)} {'is' if len(missing) == 1 else 'are'} null")
    obstacles = tuple(
        Obstacle(o["shape"], _tuple(o["center"]), _tuple(o["size"]), _tuple(o["quat"]), _tuple(o["rgba"]))
        for o in row[S.OBSTACLES] or ()
    )
    debris = tuple(
        DebrisMotion(
            _tuple(m["velocity"]),
            _tuple(m["angular_velocity"]),
            bool(m["intercept"]),
            m["t_star"],
            m["crossing_time"],
            _tuple(m["aim"]),
        )
        for m in row[S.DEBRIS_MOTION]
    )
    body = row[S.BODY]
    body = BodyParameters(float(body["mass_scale"]), _tuple(body["inertia_scale"]), _tuple(body["com_offset"]))
    if not (body.mass_scale > 0 and min(body.inertia_scale) > 0 and _finite(*body.com_offset)):
        raise ValueError(f"body {body} needs mass_scale > 0, inertia_scale > 0 and a finite com_offset")
    fault = row[S.FAULT]
    fault = ThrusterFault(str(fault["kind"]), int(fault["thruster"]), float(fault["level"]), int(fault["onset_step"]))
    mean_motion = float(row[S.MEAN_MOTION])
    if not (_finite(mean_motion) and mean_motion >= 0):
        raise ValueError(f"mean_motion {mean_motion} must be finite and >= 0")
    for m in debris:
        if not _finite(*m.velocity, *m.angular_velocity):
            raise ValueError(f"debris velocity {m.velocity} or angular velocity {m.angular_velocity} is not finite")
    dynamics = Dynamics(
        debris,
        bool(row[S.CW]),
        mean_motion,
        body,
        fault,
        Sensing(**row[S.SENSING]),
        int(row.get(S.UNSURVIVABLE_DRAWS) or 0),
    )
    return Scenario(obstacles, _tuple(row[S.GOAL]), seed=int(row[S.SEED]), dynamics=dynamics)


def episode_records(table: pa.Table, source: str, sink: Sink) -> dict[int, EpisodeRecord]:
    """episode_index -> record of every row of an episodes shard whose dynamic record is well formed;
    the others are reported (``dynamics.record``, one line each)."""
    out = {}
    for row in table.to_pylist():
        index = row.get(S.EPISODE_INDEX)
        if index is None or row.get(S.DATA_FILE) is None:
            continue  # reported by episodes.table
        try:
            scenario = _record(row)
        except (ValueError, TypeError, KeyError) as exc:
            sink.add(C.DYN_RECORD, f"the episode's dynamic record is malformed: {exc}", source, index)
            continue
        out[index] = EpisodeRecord(index, row[S.DATA_FILE], row[S.ROW_START], row[S.ROW_END], scenario)
    return out


def step_body(records: dict[int, EpisodeRecord], episodes: np.ndarray) -> tuple[StepBody, np.ndarray]:
    """The record of each step's episode as arrays, and which steps have one (a well-formed record)."""
    known = np.array([int(e) in records for e in episodes], dtype=bool)
    n = len(episodes)
    body = StepBody.nominal(n)
    for e in np.unique(episodes[known]):
        body.fill(episodes == e, records[int(e)].dynamics)
    return body, known
