"""Risky level: PD straight to the goal, blind to obstacles."""

from __future__ import annotations

import numpy as np

from orbitdata.pilots.base import Pilot, face, goal_seeking_accel
from orbitdata.scenario.spec import Scenario


class RiskyPilot(Pilot):
    """Flies the line of sight to the goal at ``cruise`` m/s (or the initial speed, if faster),
    camera on the goal. Deterministic: it draws no random numbers."""

    level = "risky"

    def __init__(self, cruise: float = 2.0, **kwargs):
        super().__init__(**kwargs)
        self.cruise = cruise

    def reset(self, scenario: Scenario, seed: int) -> None:
        self.goal = np.asarray(scenario.goal, dtype=np.float64)
        self._cruise = max(self.cruise, float(np.linalg.norm(scenario.initial_velocity)))

    def act(self, state: np.ndarray) -> np.ndarray:
        accel = goal_seeking_accel(self.controller, state, self.goal, self._cruise)
        return self.controller.thrust(state, accel, face(self.controller, state, self.goal - state[0:3]))
