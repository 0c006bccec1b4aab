"""The one module that touches orbitdata's pilot interface.

MERGE (issue 10): orbitdata's ``fly`` package replaces everything below::

    from orbitdata.fly import Task, fly_episode, EpisodeResult, CellResult, grid_report
    from orbitdata.fly.grid import check_grid

and the planner's factories are registered there (``orbitdata.fly.register_pilot`` or the
``orbitdata.pilots`` entry points in pyproject.toml). Until then this mirrors issue 10's loop:
the pilot is reset with a :class:`Task` (the scenario only if it declares ``privileged``) and
``act`` gets the whole observation dict, as ``orbitdata.fly.rollout.fly_episode`` does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitdata.grid import CellResult, grid_report  # noqa: F401  (re-exported for closed_loop)
from orbitdata.rollout import EpisodeResult, FrameSink
from orbitdata.schema import ACTION_DIM, DEPTH_LOW_SIDE, STATE_DIM
from orbitdata.sim.env import CubeSatEnv


@dataclass(frozen=True)
class Task:
    """What every pilot is told when an episode starts (``orbitdata.fly.Task``)."""

    goal: tuple[float, float, float]
    goal_radius: float
    initial_velocity: tuple[float, float, float]
    seed: int


def check_grid(obstacles: list[int], speeds: list[float], episodes: int) -> None:
    if not obstacles or not speeds:
        raise ValueError("the grid is empty: give at least one obstacle count and one speed")
    if any(n < 0 for n in obstacles):
        raise ValueError(f"obstacle counts must be >= 0, got {obstacles}")
    if any(not np.isfinite(v) or v < 0 for v in speeds):
        raise ValueError(f"speeds must be finite and >= 0 m/s, got {speeds}")
    if episodes < 1:
        raise ValueError(f"episodes per setting must be >= 1, got {episodes}")


def fly_episode(env: CubeSatEnv, pilot, seed: int, n_obstacles: int, speed: float,
                frame_sink: FrameSink | None = None) -> EpisodeResult:
    """Reset ``env`` with ``seed``, fly ``pilot`` until the episode ends (issue 10's loop)."""
    obs, info = env.reset(seed=seed, options={"n_obstacles": n_obstacles, "speed": speed})
    scn = env.scenario
    task = Task(goal=scn.goal, goal_radius=scn.goal_radius, initial_velocity=scn.initial_velocity, seed=seed)
    if pilot.privileged:
        pilot.reset(task, scenario=scn)
    else:
        pilot.reset(task)
    if pilot.needs_images and "image" not in obs:
        raise ValueError(f"pilot {pilot.name!r} needs camera images, but the env does not render")
    n = env.sim.max_steps
    states, actions = np.zeros((n, STATE_DIM), np.float32), np.zeros((n, ACTION_DIM), np.float32)
    collision, success, clearance = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, np.float32)
    depth_low = np.zeros((n, DEPTH_LOW_SIDE, DEPTH_LOW_SIDE), np.float32) if env.sim.render else None
    t = 0
    while True:
        states[t], clearance[t] = obs["state"], info["min_clearance"]
        collision[t], success[t] = info["collision"], info["success"]
        if depth_low is not None:
            depth_low[t] = obs["depth_low"]
        if frame_sink is not None and "image" in obs:
            frame_sink(t, obs["image"], obs["depth"], obs["depth_low"])
        if info["outcome"] is not None:
            break
        action = np.asarray(pilot.act(obs), dtype=np.float32)
        actions[t] = action
        obs, _, _, _, info = env.step(action.astype(np.float64))
        t += 1
    L = t + 1
    return EpisodeResult(scenario=scn, level=pilot.name, seed=seed, outcome=info["outcome"], states=states[:L],
                         actions=actions[:L], collision=collision[:L], success=success[:L],
                         min_clearance=clearance[:L], depth_low=None if depth_low is None else depth_low[:L],
                         pilot_info=pilot.metadata())
