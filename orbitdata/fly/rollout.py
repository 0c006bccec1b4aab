"""Fly one episode: a pilot in the simulator, frame by frame, recording what happened.

Both ``orbitdata fly`` (evaluation grid) and ``orbitdata generate`` (the dataset) use this
loop, so the data and the success tables come from the same code. The pilot gets the
:class:`~orbitdata.fly.pilot.Task` and each observation; only a privileged pilot also gets the
scenario (the true obstacles).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from orbitdata.fly.pilot import Pilot, Task
from orbitdata.scenario.spec import Scenario
from orbitdata.schema import ACTION_DIM, DEPTH_LOW_SIDE, STATE_DIM
from orbitdata.sim.env import CubeSatEnv

# Called once per frame with (frame_index, rgb (H, W, 3) uint8, depth (H, W) float32 m,
# depth_low (16, 16) float32 m) when the env renders.
FrameSink = Callable[[int, np.ndarray, np.ndarray, np.ndarray], None]


@dataclass
class EpisodeResult:
    """Low-dimensional record of one flown episode; row t follows the schema's semantics."""

    scenario: Scenario
    pilot: str  # the pilot's name (the level, for the dataset's pilots)
    seed: int
    outcome: str
    states: np.ndarray  # (L, 16) float32
    actions: np.ndarray  # (L, 8) float32, last row zeros (terminal frame)
    collision: np.ndarray  # (L,) bool
    success: np.ndarray  # (L,) bool
    min_clearance: np.ndarray  # (L,) float32 metres
    depth_low: np.ndarray | None = None  # (L, 16, 16) float32 metres when rendered
    pilot_info: dict = field(default_factory=dict)

    @property
    def length(self) -> int:
        return len(self.states)


SENSOR_KEYS = ("depth", "depth_low")  # the rendered depth: only a pilot that sees_depth gets it


def without_depth(obs: dict) -> dict:
    """The observation a camera-only pilot gets: the state and the image, not the rendered depth."""
    return {k: v for k, v in obs.items() if k not in SENSOR_KEYS}


def pilot_view(obs: dict, pilot, image_quality: int | None = None) -> dict:
    """What ``pilot`` is handed of ``obs``: the rendered depth only if it ``sees_depth``, and with
    ``image_quality`` the image round-tripped through the dataset's JPEG codec at that quality,
    so that a pilot trained on the dataset sees what it trained on."""
    seen = obs if getattr(pilot, "sees_depth", False) else without_depth(obs)
    if image_quality is not None and "image" in seen:
        from orbitdata.codecs import decode_rgb, encode_rgb

        seen = {**seen, "image": decode_rgb(encode_rgb(seen["image"], image_quality))}
    return seen


def fly_episode(
    env: CubeSatEnv,
    pilot: Pilot,
    seed: int,
    n_obstacles: int | None = None,
    speed: float | None = None,
    scenario: Scenario | None = None,
    frame_sink: FrameSink | None = None,
    image_quality: int | None = None,
) -> EpisodeResult:
    """Reset ``env`` with ``seed`` (or the given scenario), fly ``pilot`` until the episode ends.
    ``image_quality``: hand the pilot its camera through the dataset's JPEG codec (see
    :func:`pilot_view`); the recorded frames stay the raw renders."""
    options = {"scenario": scenario} if scenario is not None else {"n_obstacles": n_obstacles, "speed": speed}
    if pilot.needs_images and not env.sim.render:
        raise ValueError(
            f"pilot {pilot.name!r} needs camera images, but the env does not render: use SimConfig(render=True)"
        )
    obs, info = env.reset(seed=seed, options=options)
    scn = env.scenario
    task = Task(goal=scn.goal, goal_radius=scn.goal_radius, initial_velocity=scn.initial_velocity, seed=seed)
    if pilot.privileged:
        pilot.reset(task, scenario=scn)
    else:
        pilot.reset(task)
    max_frames = env.sim.max_steps
    states = np.zeros((max_frames, STATE_DIM), np.float32)
    actions = np.zeros((max_frames, ACTION_DIM), np.float32)
    collision = np.zeros(max_frames, bool)
    success = np.zeros(max_frames, bool)
    clearance = np.zeros(max_frames, np.float32)
    depth_low = np.zeros((max_frames, DEPTH_LOW_SIDE, DEPTH_LOW_SIDE), np.float32) if env.sim.render else None
    t = 0
    while True:
        states[t] = obs["state"]
        clearance[t] = info["min_clearance"]
        collision[t] = info["collision"]
        success[t] = info["success"]
        if depth_low is not None:
            depth_low[t] = obs["depth_low"]
        if frame_sink is not None and "image" in obs:
            frame_sink(t, obs["image"], obs["depth"], obs["depth_low"])
        if info["outcome"] is not None:
            break
        action = np.asarray(pilot.act(pilot_view(obs, pilot, image_quality)), dtype=np.float32)
        actions[t] = action
        obs, _, _, _, info = env.step(action.astype(np.float64))
        t += 1
    length = t + 1
    return EpisodeResult(
        scenario=env.scenario,
        pilot=pilot.name,
        seed=seed,
        outcome=info["outcome"],
        states=states[:length],
        actions=actions[:length],
        collision=collision[:length],
        success=success[:length],
        min_clearance=clearance[:length],
        depth_low=None if depth_low is None else depth_low[:length],
        pilot_info=pilot.metadata(),
    )
