"""The pilot interface: what a pilot is told at the start of an episode, and what it sees each step.

A pilot is reset with a :class:`Task` (the goal, its radius, the initial velocity and the
episode seed) and then maps each observation to 8 thrusts in [0, 1]::

    class MyPilot(Pilot):
        name = "mine"
        needs_images = True                  # it reads obs["image"] (and with sees_depth = True, the
                                             # rendered obs["depth"] / obs["depth_low"])

        def reset(self, task: Task) -> None:
            self.goal = np.asarray(task.goal)  # metres, world frame relative to the start

        def act(self, obs: dict) -> np.ndarray:
            state = obs["state"]             # (16,) float32, see orbitdata.state
            image = obs["image"]             # (H, W, 3) uint8, when the env renders
            return np.zeros(8)               # normalised thrusts in [0, 1]

The obstacle list is ground truth that a real spacecraft does not have: only a pilot that
declares ``privileged = True`` (the expert, which plans with RRT* around the true obstacles)
is also handed the :class:`~orbitdata.scenario.spec.Scenario`, as ``reset(task, scenario=...)``.
Register a pilot with :func:`orbitdata.fly.register_pilot` (or an ``orbitdata.pilots`` entry
point) and ``orbitdata fly --pilot mine`` flies it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Task:
    """What every pilot is told when an episode starts.

    Attributes:
        goal: centre of the goal region, metres, world frame relative to the start (p_0 = 0).
        goal_radius: metres; the episode succeeds when the CubeSat's centre enters the region.
        initial_velocity: m/s, world frame, at frame 0 (the first state has it in the body
            frame, rounded to float32; this is the exact value).
        seed: the episode seed; a pilot draws all its randomness from it
            (``orbitdata.seeding.rng(seed, "pilot")``), so that an episode is reproducible.
    """

    goal: tuple[float, float, float]
    goal_radius: float
    initial_velocity: tuple[float, float, float]
    seed: int


class Pilot(ABC):
    """Flies one episode at a time: ``reset(task)``, then ``act(obs)`` every control step.

    Observations (see :class:`orbitdata.sim.CubeSatEnv`): ``state`` (16,) float32 always;
    ``image`` (H, W, 3) uint8 when the env renders; and only for a pilot that ``sees_depth``, the
    rendered ``depth`` (H, W) float32 metres (0 = no return) and ``depth_low`` (16, 16) float32
    metres: a perfect depth sensor, which a camera-only pilot does not have. ``act`` returns 8
    thrusts in [0, 1]. One pilot may fly many episodes: ``reset`` starts each one afresh.

    Class attributes, each a default an instance may set for itself (a planner picks its name,
    camera and privilege from the variant it flies):
        name: the registry name (and the ``level`` column for the built-in levels).
        privileged: ``reset`` also gets ``scenario=``, the ground truth (obstacles included).
        needs_images: ``act`` reads the camera, so the env must render.
        sees_depth: ``act`` is given the rendered depth as well (a privileged sensor).
        image_codec: ``act`` sees its camera through the dataset's JPEG codec, as a pilot trained
            on the dataset's frames saw them (``orbitdata fly --image-codec`` asks it of any pilot).
    """

    name: str = ""
    privileged: bool = False
    needs_images: bool = False
    sees_depth: bool = False
    image_codec: bool = False

    @abstractmethod
    def reset(self, task: Task) -> None:
        """Start an episode. A privileged pilot's signature is ``reset(task, scenario)``."""

    @abstractmethod
    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(8,) normalised thrusts in [0, 1] for this control step."""

    def metadata(self) -> dict:
        """Per-episode facts for the episodes table (the expert reports its planner)."""
        return {}
