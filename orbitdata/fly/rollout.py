"""Fly one episode: a pilot in the simulator, frame by frame, recording what happened.

Both ``orbitdata fly`` (evaluation grid) and ``orbitdata generate`` (the dataset) use this
loop, so the data and the success tables come from the same code. The pilot gets the
:class:`~orbitdata.fly.pilot.Task` and each observation; only a privileged pilot also gets the
scenario (the true obstacles). :class:`Flight` is the loop a frame at a time, for callers that
step several episodes together (``orbitmodel``'s lockstep flights).
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
    # (L, N, 7) float32: each obstacle's centre (m, world) and quat (w, x, y, z) at every frame,
    # recorded when the scenario moves (has dynamics); privileged, never handed to the pilot.
    obstacle_poses: np.ndarray | None = None

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


class Flight:
    """One episode in flight, a frame at a time: constructing it resets ``env`` with ``seed`` (or
    the given scenario) and the pilot with the task, and records frame 0; :meth:`step` executes
    one action and records the frame it leads to; :meth:`result` is the record once :attr:`done`.

    :func:`fly_episode` is this loop with the pilot's own ``act``; ``orbitmodel``'s lockstep
    flights (``orbitmodel.evaluate.lockstep``) step several flights with one batched call.
    ``image_quality``: hand the pilot its camera through the dataset's JPEG codec (see
    :func:`pilot_view`); the recorded frames stay the raw renders.
    """

    def __init__(
        self,
        env: CubeSatEnv,
        pilot: Pilot,
        seed: int,
        n_obstacles: int | None = None,
        speed: float | None = None,
        scenario: Scenario | None = None,
        frame_sink: FrameSink | None = None,
        image_quality: int | None = None,
    ):
        options = {"scenario": scenario} if scenario is not None else {"n_obstacles": n_obstacles, "speed": speed}
        if seed is None and scenario is None:
            raise ValueError("an episode needs a seed (or scenario=..., an episode's Scenario)")
        if pilot.needs_images and not env.sim.render:
            raise ValueError(
                f"pilot {pilot.name!r} needs camera images, but the env does not render: use SimConfig(render=True)"
            )
        self.env, self.pilot, self.seed = env, pilot, seed
        self.frame_sink, self.image_quality = frame_sink, image_quality
        self.obs, self.info = env.reset(seed=seed, options=options)
        scn = env.scenario
        task = Task(goal=scn.goal, goal_radius=scn.goal_radius, initial_velocity=scn.initial_velocity, seed=seed)
        if pilot.privileged:
            pilot.reset(task, scenario=scn)
        else:
            pilot.reset(task)
        max_frames = env.sim.max_steps
        self.states = np.zeros((max_frames, STATE_DIM), np.float32)
        self.actions = np.zeros((max_frames, ACTION_DIM), np.float32)
        self.collision = np.zeros(max_frames, bool)
        self.success = np.zeros(max_frames, bool)
        self.clearance = np.zeros(max_frames, np.float32)
        self.depth_low = np.zeros((max_frames, DEPTH_LOW_SIDE, DEPTH_LOW_SIDE), np.float32) if env.sim.render else None
        moving = scn.dynamics is not None
        self.poses = np.zeros((max_frames, len(scn.obstacles), 7), np.float32) if moving else None
        self.t = 0
        self._record()

    @property
    def done(self) -> bool:
        """The episode has ended (its outcome is known)."""
        return self.info["outcome"] is not None

    def view(self) -> dict:
        """What the pilot is handed of the current observation (:func:`pilot_view`)."""
        return pilot_view(self.obs, self.pilot, self.image_quality)

    def step(self, action) -> None:
        """Execute ``action`` (8,) thrusts from the current frame; record the next frame."""
        action = np.asarray(action, dtype=np.float32)
        if action.shape != self.actions.shape[1:]:
            raise ValueError(
                f"pilot {self.pilot.name!r} gave an action of shape {action.shape} at frame {self.t}: "
                f"give {self.actions.shape[1]} thrusts in [0, 1]"
            )
        self.actions[self.t] = action
        self.obs, _, _, _, self.info = self.env.step(action.astype(np.float64))
        self.t += 1
        self._record()

    def _record(self) -> None:
        t, obs, info = self.t, self.obs, self.info
        self.states[t] = obs["state"]
        self.clearance[t] = info["min_clearance"]
        self.collision[t] = info["collision"]
        self.success[t] = info["success"]
        if self.depth_low is not None:
            self.depth_low[t] = obs["depth_low"]
        if self.poses is not None:
            self.poses[t] = info["obstacle_poses"]
        if self.frame_sink is not None and "image" in obs:
            self.frame_sink(t, obs["image"], obs["depth"], obs["depth_low"])

    def result(self) -> EpisodeResult:
        """The episode's record (frames 0..t)."""
        length = self.t + 1
        return EpisodeResult(
            scenario=self.env.scenario,
            pilot=self.pilot.name,
            seed=self.seed,
            outcome=self.info["outcome"],
            states=self.states[:length],
            actions=self.actions[:length],
            collision=self.collision[:length],
            success=self.success[:length],
            min_clearance=self.clearance[:length],
            depth_low=None if self.depth_low is None else self.depth_low[:length],
            pilot_info=self.pilot.metadata(),
            obstacle_poses=None if self.poses is None else self.poses[:length],
        )


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
    flight = Flight(env, pilot, seed, n_obstacles, speed, scenario, frame_sink, image_quality)
    while not flight.done:
        flight.step(pilot.act(flight.view()))
    return flight.result()
