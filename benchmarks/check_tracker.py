"""Does the tracker put the debris where it will be? Its knobs, scored on validation episodes.

    python benchmarks/check_tracker.py RUN DATASET [--episodes 136] [--json OUT]

On the run's validation episodes (the train-split episodes it held out), every frame's recorded
16x16 depth (``observation.depth_low``, what ``oracle-true-dyn-sensor`` sees in place of the depth
head) is fed, as the planner feeds it, to the tracker with each setting of its knobs
(``SETTINGS``), and to the static planner's 50-frame point memory. Every 10th frame t, each is
asked for the clearance at query points k = 10, 25 and 50 frames ahead (0.4, 1 and 2 s): 96
points drawn uniformly in a 3 m ball around where the recorded flight was at t + k (the same
points for every setting). The answer is set against the clearance to the
debris where they really were then (the privileged poses, read here only to score):

- missed: of the points that were in danger (within the hull plus the cost's margin of a true
  surface), the share the setting calls safe;
- false alarm: of the points at least 0.5 m beyond danger, the share the setting calls in danger.

A point the camera never saw is missed by every setting alike. Beside these, each track seen at a
scored frame has its velocity set against the true velocity of the debris nearest its points
(mean error, m/s, and the same for a velocity of zero). Prints figures and writes them as JSON;
asserts nothing. The flights are ``--set obstacle_motion=tracker --set KNOB=VALUE``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
import torch

from orbitdata import schema as S
from orbitdata.cli.errors import run_script, script_help
from orbitdata.load.episodes import load_episode
from orbitdata.load.rows import read_rows
from orbitdata.sim.config import SimConfig
from orbitmodel.plan.config import PlannerConfig
from orbitmodel.plan.cost import CostConfig
from orbitmodel.plan.obstacles import Camera, PointMemory, TrueObstacles, border_points, depth_to_points
from orbitmodel.plan.tracker import Tracker, TrackerConfig
from orbitmodel.runs import read_run_config

AHEAD = (10, 25, 50)  # frames
EVERY, QUERIES, BALL, CLEAR = 10, 96, 3.0, 0.5

# The settings scored, each a change to START (the tracker's knobs before this choice): START, one
# knob at a time, then the best of those together. The chosen one is TrackerConfig's default.
START = TrackerConfig(point_frames=10, link=0.5, confidence=0.0)
SETTINGS = {
    "start": {},
    "window=10": {"window": 10},
    "window=50": {"window": 50, "min_frames": 8},
    "point_frames=3": {"point_frames": 3},
    "point_frames=1": {"point_frames": 1},
    "point_frames=25": {"point_frames": 25},
    "min_frames=4": {"min_frames": 4},
    "min_frames=16": {"min_frames": 16},
    "gate=1.0": {"gate": 1.0},
    "link=0.25": {"link": 0.25},
    "speed_cap=0 (no motion)": {"speed_cap": 0.0},
    "forget=10": {"forget": 10},
    "confidence=2": {"confidence": 2.0},
    "confidence=3": {"confidence": 3.0},
    "point_frames=25, speed_cap=0 (no motion)": {"point_frames": 25, "speed_cap": 0.0},
    "point_frames=25, confidence=2": {"point_frames": 25, "confidence": 2.0},
    "point_frames=25, confidence=3": {"point_frames": 25, "confidence": 3.0},
    "point_frames=25, confidence=3, link=0.25 (chosen)": {"point_frames": 25, "confidence": 3.0, "link": 0.25},
    "point_frames=25, confidence=3, min_frames=16": {"point_frames": 25, "confidence": 3.0, "min_frames": 16},
    "window=50, point_frames=50, confidence=3": {"window": 50, "point_frames": 50, "confidence": 3.0},
}


def depth_maps(episode) -> np.ndarray:
    """(L, 16, 16) metres: the episode's recorded depth_low."""
    m = episode.meta
    rows = read_rows(episode.root / m[S.DATA_FILE], m[S.ROW_START], m[S.ROW_END], [S.DEPTH_LOW])
    col = rows.column(S.DEPTH_LOW).combine_chunks()
    return col.values.to_numpy(zero_copy_only=False).reshape(len(col), S.DEPTH_LOW_SIDE, S.DEPTH_LOW_SIDE)


def queries(episode) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    """(t, k, points (Q, 3), true clearance (Q,)) of every scored frame and horizon."""
    truth = TrueObstacles(episode.scenario)
    positions = episode.positions.astype(np.float64)
    out = []
    for t in range(EVERY, len(episode), EVERY):
        for k in AHEAD:
            if t + k >= len(episode):
                continue
            rng = np.random.default_rng([episode.index, t, k])
            direction = rng.normal(size=(QUERIES, 3))
            direction /= np.linalg.norm(direction, axis=1, keepdims=True)
            radius = BALL * rng.random(QUERIES) ** (1 / 3)
            points = positions[t + k] + direction * radius[:, None]
            time = torch.tensor([(t + k) * S.DT], dtype=torch.float64)
            clearance = truth.clearance(torch.from_numpy(points)[:, None], time)[:, 0].numpy()
            out.append((t, k, points, clearance))
    return out


def seen(episode, plan: PlannerConfig, camera: Camera) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each frame's (points (n, 3), radii (n,), on the image border (n,)), as the planner makes them."""
    states, maps = episode.states.astype(np.float64), depth_maps(episode)
    return [
        (
            *depth_to_points(maps[t], states[t], camera, plan.max_range, plan.footprint, plan.support),
            border_points(maps[t], camera, plan.max_range, plan.support),
        )
        for t in range(len(episode))
    ]


def true_motion(episode) -> tuple[np.ndarray, np.ndarray]:
    """(L, N, 3) metres and (L, N, 3) m/s: each obstacle's centre and velocity (central differences)
    at every frame."""
    centres = episode.scenario.obstacle_poses(np.arange(-1, len(episode) + 1) * S.DT)[..., :3]  # (L + 2, N, 3)
    return centres[1:-1], (centres[2:] - centres[:-2]) / (2 * S.DT)


def flown(memory, frames, motion, reach: float, asked) -> tuple[list[np.ndarray], list]:
    """The clearance (Q,) ``memory`` (a Tracker, or a PointMemory) fed ``frames`` (:func:`seen`)
    predicts at each of ``asked``, and (a tracker's) [(velocity error, zero velocity's error)] m/s
    of its tracks seen at those frames, against ``motion`` (:func:`true_motion`)."""
    by_frame: dict[int, list] = {}
    for i, (t, k, points, _) in enumerate(asked):
        by_frame.setdefault(t, []).append((i, k, points))
    out: list[np.ndarray] = [None] * len(asked)
    speeds = []
    memory.reset()
    for t, (points, radii, edge) in enumerate(frames):
        if isinstance(memory, Tracker):
            memory.add(points, radii, t * S.DT, edge)
        else:
            memory.add(points, radii)
        if t not in by_frame:
            continue
        field = memory.field(t * S.DT, reach) if isinstance(memory, Tracker) else memory.cloud(reach)
        for track in memory.tracks if isinstance(memory, Tracker) else []:
            if track.unseen == 0:
                centres, velocities = motion[0][t], motion[1][t]
                nearest = np.linalg.norm(track.frames[-1].points[:, None] - centres[None], axis=-1).min(0).argmin()
                truth = velocities[nearest]
                speeds.append((float(np.linalg.norm(track.velocity - truth)), float(np.linalg.norm(truth))))
        for i, k, q in by_frame[t]:
            times = torch.tensor([(t + k) * S.DT], dtype=torch.float64)
            out[i] = field.clearance(torch.from_numpy(q).float()[:, None], times)[:, 0].numpy()
    return out, speeds


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("run", help="a run trained on the dynamic tier: its held-out validation episodes are scored")
    ap.add_argument("dataset", help="the dynamic-tier dataset the run was trained on")
    ap.add_argument("--episodes", type=int, default=None, help="score only the first N validation episodes")
    ap.add_argument("--json", type=Path, help="write the figures here")
    ap.add_argument("--settings", nargs="+", help="score only these of SETTINGS (names as printed, without 'tracker ')")
    args = ap.parse_args()
    torch.set_num_threads(1)
    held = sorted(read_run_config(args.run).validation.episodes)[: args.episodes]
    plan, danger = PlannerConfig(), CostConfig().hull_radius + CostConfig().margin
    camera = Camera.from_sim(SimConfig(render=False))
    memories = {"static point memory (50 frames)": lambda: PointMemory(plan.memory_frames)}
    memories |= {
        f"tracker {name}": (lambda knobs=knobs: Tracker(dataclasses.replace(START, **knobs)))
        for name, knobs in SETTINGS.items()
        if not args.settings or name in args.settings
    }
    tallies = {name: {k: np.zeros(4, int) for k in AHEAD} for name in memories}  # danger, missed, clear, alarm
    speeds: dict[str, list] = {name: [] for name in memories}
    for e in held:
        episode = load_episode(Path(args.dataset), e)
        asked, frames, motion = queries(episode), seen(episode, plan, camera), true_motion(episode)
        for name, make in memories.items():
            predicted, errors = flown(make(), frames, motion, plan.reach, asked)
            speeds[name] += errors
            for (_, k, _, truth), guess in zip(asked, predicted):
                inside, clear = truth < danger, truth >= danger + CLEAR
                tallies[name][k] += [
                    inside.sum(),
                    (inside & (guess >= danger)).sum(),
                    clear.sum(),
                    (clear & (guess < danger)).sum(),
                ]
    rows = []
    print(f"{len(held)} validation episodes of {args.dataset}; danger = within {danger:.2f} m of a surface")
    print(f"{'memory':<50} " + "  ".join(f"{k:>2} ahead: missed  alarm" for k in AHEAD) + "  velocity error (zero's)")
    for name, tally in tallies.items():
        row = {"memory": name}
        if speeds[name]:
            errors = np.array(speeds[name])
            row["velocity"] = {"tracks": len(errors), "error": errors[:, 0].mean(), "zero_error": errors[:, 1].mean()}
        for k, (inside, missed, clear, alarm) in tally.items():
            row[str(k)] = {
                "danger": int(inside),
                "missed": missed / max(inside, 1),
                "clear": int(clear),
                "false_alarm": alarm / max(clear, 1),
            }
        rows.append(row)
        velocity = row.get("velocity")
        print(
            f"{name:<50} "
            + "  ".join(f"         {row[str(k)]['missed']:.3f}  {row[str(k)]['false_alarm']:.3f}" for k in AHEAD)
            + (f"  {velocity['error']:.3f} ({velocity['zero_error']:.3f})" if velocity else "")
        )
    if args.json:
        args.json.write_text(
            json.dumps(
                {"run": str(args.run), "dataset": str(args.dataset), "episodes": held, "danger": danger, "rows": rows},
                indent=1,
            )
            + "\n"
        )


if __name__ == "__main__":
    run_script(main)
