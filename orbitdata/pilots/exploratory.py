"""Exploratory level: strong, temporally correlated action noise around a goal-seeking PD."""

from __future__ import annotations

import numpy as np

from orbitdata.pilots.base import Pilot, face, goal_seeking_accel
from orbitdata.scenario.spec import Scenario
from orbitdata.schema import ACTION_DIM, DT
from orbitdata.seeding import rng as make_rng


class ExploratoryPilot(Pilot):
    """Goal-seeking PD plus an Ornstein-Uhlenbeck perturbation of every thruster.

    The noise has stationary std ``sigma`` (in normalised thrust) and correlation time
    ``tau`` seconds, so it produces sustained off-nominal drifts and spins, not jitter.
    """

    level = "exploratory"

    def __init__(self, cruise: float = 1.5, sigma: float = 0.35, tau: float = 0.6, **kwargs):
        super().__init__(**kwargs)
        self.cruise, self.sigma, self.tau = cruise, sigma, tau

    def reset(self, scenario: Scenario, seed: int) -> None:
        self.goal = np.asarray(scenario.goal, dtype=np.float64)
        self._cruise = max(self.cruise, float(np.linalg.norm(scenario.initial_velocity)))
        self.rng = make_rng(seed, "pilot")
        self._decay = float(np.exp(-DT / self.tau))
        self.noise = self.rng.normal(0.0, self.sigma, ACTION_DIM)

    def act(self, state: np.ndarray) -> np.ndarray:
        accel = goal_seeking_accel(self.controller, state, self.goal, self._cruise)
        nominal = self.controller.thrust(state, accel, face(self.controller, state, self.goal - state[0:3]))
        innovation = self.rng.normal(0.0, self.sigma * np.sqrt(1.0 - self._decay**2), ACTION_DIM)
        self.noise = self._decay * self.noise + innovation
        return np.clip(nominal + self.noise, 0.0, 1.0)
