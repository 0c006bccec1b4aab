"""Risky level: PD straight to the goal, blind to obstacles."""

from __future__ import annotations

import numpy as np

from orbitdata.fly.pilot import Task
from orbitdata.fly.pilots.common import ControlledPilot, face, goal_seeking_accel
from orbitdata.fly.pilots.config import RiskyConfig
from orbitdata.state import POSITION


class RiskyPilot(ControlledPilot):
    """Flies the line of sight to the goal at ``cruise`` m/s (or the initial speed, if faster),
    camera on the goal. Deterministic: it draws no random numbers."""

    name = "risky"

    def __init__(self, config: RiskyConfig = RiskyConfig(), **kwargs):
        super().__init__(**kwargs)
        self.config = config

    def reset(self, task: Task) -> None:
        self.goal = np.asarray(task.goal, dtype=np.float64)
        self._cruise = max(self.config.cruise, float(np.linalg.norm(task.initial_velocity)))

    def act(self, obs: dict) -> np.ndarray:
        state = obs["state"]
        accel = goal_seeking_accel(self.controller, state, self.goal, self._cruise)
        return self.controller.thrust(state, accel, face(self.controller, state, self.goal - state[POSITION]))
