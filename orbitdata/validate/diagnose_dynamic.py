"""What is wrong with an episode whose dynamics the row checks flagged: one line per episode.

The driver reads each flagged episode whole and tries the record's likely culprits one at a
time, keeping the rest of the record:

* the CW flag the other way: if then the CubeSat's steps and the debris' poses all fit, the
  finding is ``dynamics.cw`` and names the flag (one line for both motions);
* the thruster fault: none at all, or the recorded kind and level on each thruster from the
  frame at which the motion first leaves the healthy thrusters; a fit names the fault record
  (``dynamics.thrust``) and what the motion shows instead;
* otherwise ``dynamics.thrust`` says how many steps are off, by how much and from which frame,
  and ``dynamics.debris`` which obstacle's poses leave their motion, and whether a single pose
  jumps (the frames on either side fit) or the motion itself differs.

Reading is bounded: at most ``MAX_DIAGNOSED`` episodes are read again; the others get a line
from what the row checks counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orbitdata import schema as S
from orbitdata.load.rows import RowReader
from orbitdata.scenario.dynamics import NO_FAULT
from orbitdata.sim.rigid_body import FAULT_KINDS, StepBody
from orbitdata.validate import checks as C
from orbitdata.validate.checks_dynamic import (
    Flag,
    Physics,
    Poses,
    expected_poses,
    pose_errors,
    pose_fits,
    step_thrust,
    steps_of,
    thrust_fits,
)
from orbitdata.validate.dynamic_record import EpisodeRecord
from orbitdata.validate.frames import Frames
from orbitdata.validate.report import Sink

MAX_DIAGNOSED = 100
COLUMNS = [
    S.EPISODE_INDEX,
    S.FRAME_INDEX,
    S.TIMESTAMP,
    S.STATE,
    S.ACTION,
    S.COLLISION,
    S.SUCCESS,
    S.IS_LAST,
    S.MIN_CLEARANCE,
    S.OBSTACLE_POSES,
]


@dataclass
class Verdict:
    """One motion (the CubeSat's steps or the debris' poses) against the record and the CW flip."""

    fits: bool  # every step / pose fits the record as it is
    fits_flipped: bool  # every one fits with the cw flag the other way
    line: str = ""  # what is wrong, when it does not fit


def _fault_text(kind: str, thruster: int, level: float, onset: int | None = None) -> str:
    if kind == NO_FAULT:
        return "no fault"
    level_text = {"off": "", "scaled": f" x {level:.3g}", "stuck": f" at {level:.3g}"}[kind]
    return f"thruster {thruster} {kind}{level_text}" + (f" from frame {onset}" if onset is not None else "")


def _recorded_fault(record: EpisodeRecord) -> str:
    f = record.dynamics.fault
    return _fault_text(f.kind, f.thruster, f.level, f.onset_step)


def _flipped_n(record: EpisodeRecord) -> float:
    dyn = record.dynamics
    return 0.0 if dyn.cw else dyn.mean_motion


def thrust_verdict(a: Frames, b: Frames, record: EpisodeRecord, physics: Physics) -> Verdict:
    """The episode's steps (pairs a -> b) against the record, the CW flip and the fault's culprits."""
    idx, body = steps_of(a, b, {record.index: record})
    frames = a.frame[idx]

    def fits(hypothesis: StepBody) -> np.ndarray:
        with np.errstate(invalid="ignore", over="ignore"):
            return thrust_fits(step_thrust(a, b, idx, hypothesis, physics))

    as_recorded = fits(body)
    flipped = fits(body.replace(n=np.full(len(idx), _flipped_n(record))))
    verdict = Verdict(bool(as_recorded.all()), bool(flipped.all()))
    if verdict.fits:
        return verdict
    fault = record.dynamics.fault
    healthy = fits(body.replace(fault_kind=np.zeros(len(idx), int))) if fault.kind != NO_FAULT else as_recorded
    if fault.kind != NO_FAULT and healthy.all():
        verdict.line = (
            f"the motion shows no thruster fault (every step follows the commanded thrust), but the record "
            f"has {_recorded_fault(record)}: the fault record is wrong"
        )
        return verdict
    # The motion leaves the healthy thrusters here: which single fault from then on explains it?
    start = int(frames[np.flatnonzero(~healthy)[0]])
    before = frames < start
    if healthy[before].all():
        if fault.kind != NO_FAULT:  # the recorded kind and level, on each thruster
            kinds = [(fault.kind, k, fault.level) for k in [fault.thruster, *range(S.ACTION_DIM)] if k >= 0]
        else:  # no fault recorded: a dead thruster is the one fault whose level need not be guessed
            kinds = [("off", k, 0.0) for k in range(S.ACTION_DIM)]
        for kind, k, level in dict.fromkeys(kinds):
            hypothesis = body.replace(
                fault_kind=np.full(len(idx), FAULT_KINDS.index(kind)),
                fault_thruster=np.full(len(idx), k),
                fault_level=np.full(len(idx), level),
                onset=np.zeros(len(idx), int),
            )
            if fits(hypothesis)[~before].all():
                shows = (
                    "the recorded fault" if (kind, k) == (fault.kind, fault.thruster) else _fault_text(kind, k, level)
                )
                verdict.line = (
                    f"the motion shows {shows} from frame {start} at the latest, but the record has "
                    f"{_recorded_fault(record)}: the fault record is wrong"
                )
                return verdict
    verdict.line = _thrust_line(a, b, idx, body, physics, as_recorded, record)
    return verdict


def _thrust_line(
    a: Frames, b: Frames, idx: np.ndarray, body: StepBody, physics: Physics, fits: np.ndarray, record: EpisodeRecord
) -> str:
    res = step_thrust(a, b, idx, body, physics)
    bad = ~fits
    first = int(a.frame[idx][np.flatnonzero(bad)[0]])
    cw = record.dynamics.cw
    return (
        f"{int(bad.sum())} of {len(idx)} steps do not follow the commanded thrust through the record "
        f"({_recorded_fault(record)}, cw {str(cw).lower()}): off by up to {np.nanmax(res.velocity[bad]):.3g} m/s, "
        f"{np.nanmax(res.angular_velocity[bad]):.3g} rad/s, {np.nanmax(res.fuel[bad]):.3g} of the fuel, first on "
        f"the step from frame {first}; the actions or the episode's fault or body record are wrong"
    )


def debris_verdict(fr: Frames, poses: Poses, record: EpisodeRecord, dt: float) -> Verdict:
    """The episode's obstacle poses against their recorded motion and the CW flip."""
    n = len(record.scenario.obstacles)
    rows = np.flatnonzero(poses.valid & (poses.counts() == n))
    if not len(rows) or n == 0:
        return Verdict(True, True)
    recorded = poses.rows(rows, n)
    frames = fr.frame[rows]
    dist, turn = pose_errors(recorded, expected_poses(record, frames, dt))
    fits = pose_fits(dist, turn)  # (T, n)
    flipped = pose_fits(*pose_errors(recorded, expected_poses(record, frames, dt, flip_cw=True)))
    verdict = Verdict(bool(fits.all()), bool(flipped.all()))
    if verdict.fits:
        return verdict
    parts = []
    for i in np.flatnonzero(~fits.all(axis=0))[:3]:
        off = np.flatnonzero(~fits[:, i])
        worst = off[np.nanargmax(np.where(np.isnan(dist[off, i]), np.inf, dist[off, i]))]
        size = f"{dist[worst, i]:.3g} m and {turn[worst, i]:.3g} rad"
        if len(off) == 1 and 0 < off[0] < len(rows) - 1:
            parts.append(
                f"obstacle {i}'s pose jumps at frame {frames[off[0]]}: {size} from its recorded motion, which the "
                f"frames before and after follow"
            )
        elif len(off) == 1:
            parts.append(f"obstacle {i}'s pose at frame {frames[off[0]]} is {size} from its recorded motion")
        else:
            parts.append(
                f"obstacle {i}'s poses leave its recorded motion at {len(off)} of {len(rows)} frames "
                f"({frames[off[0]]}-{frames[off[-1]]}), by up to {size} (frame {frames[worst]}): the poses or "
                "the debris_motion record are wrong"
            )
    more = int((~fits.all(axis=0)).sum()) - len(parts)
    verdict.line = "; ".join(parts) + (f"; and {more} more obstacle(s)" if more > 0 else "")
    return verdict


def _read(root: Path, record: EpisodeRecord) -> tuple[Frames, Poses]:
    table = RowReader(root / record.data_file, COLUMNS).rows(record.row_start, record.row_end)
    return Frames.from_table(table, record.row_start), Poses.from_column(table.column(S.OBSTACLE_POSES))


def diagnose(
    root: Path,
    thrust: dict[int, Flag],
    debris: dict[int, Flag],
    records: dict[int, EpisodeRecord],
    physics: Physics,
    sink: Sink,
) -> None:
    """One finding per flagged episode and culprit (``dynamics.cw``, ``.thrust``, ``.debris``)."""
    for n, e in enumerate(sorted(set(thrust) | set(debris))):
        record = records[e]
        where = dict(file=record.data_file, episode=e)
        flags = [f for f in (thrust.get(e), debris.get(e)) if f is not None]
        first = min(f.first for f in flags)
        if n >= MAX_DIAGNOSED:
            if e in thrust:
                sink.add(
                    C.DYN_THRUST,
                    f"{thrust[e].count} steps do not follow the commanded thrust through the record "
                    f"({_recorded_fault(record)}, cw {str(record.dynamics.cw).lower()}), first on the step "
                    f"from frame {thrust[e].first}",
                    frame=thrust[e].first,
                    **where,
                )
            if e in debris:
                sink.add(
                    C.DYN_DEBRIS,
                    f"{debris[e].count} obstacle poses leave their recorded motion, first at frame {debris[e].first}",
                    frame=debris[e].first,
                    **where,
                )
            continue
        try:
            fr, poses = _read(root, record)
        except Exception as exc:  # the rows were readable a moment ago; say so rather than crash
            sink.add(C.DYN_THRUST, f"could not read the episode's rows again ({type(exc).__name__}: {exc})", **where)
            continue
        a, b = fr.take(slice(0, -1)), fr.take(slice(1, None))
        moves = thrust_verdict(a, b, record, physics)
        drifts = debris_verdict(fr, poses, record, physics.dt)
        if not (moves.fits and drifts.fits) and moves.fits_flipped and drifts.fits_flipped:
            whose = [w for w, v in (("the CubeSat", moves), ("the debris", drifts)) if not v.fits]
            cw = record.dynamics.cw
            shows = "shows no Clohessy-Wiltshire terms" if cw else "shows the Clohessy-Wiltshire terms"
            sink.add(
                C.DYN_CW,
                f"cw is {str(cw).lower()} in the episodes table, but the motion of {' and of '.join(whose)} {shows} "
                f"(it fits cw {str(not cw).lower()}): the cw flag is wrong",
                frame=first,
                **where,
            )
            continue
        if not moves.fits:
            sink.add(C.DYN_THRUST, moves.line, frame=thrust[e].first if e in thrust else first, **where)
        if not drifts.fits:
            sink.add(C.DYN_DEBRIS, drifts.line, frame=debris[e].first if e in debris else first, **where)
