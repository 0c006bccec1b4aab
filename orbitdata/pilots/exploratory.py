"""Exploratory level: strong, temporally correlated random actions around a goal-seeking PD."""

from __future__ import annotations

import numpy as np

from orbitdata.pilots.base import Pilot, face, goal_seeking_accel
from orbitdata.scenario.spec import Scenario
from orbitdata.schema import ACTION_DIM, DT
from orbitdata.seeding import rng as make_rng


class _OrnsteinUhlenbeck:
    """Stationary OU process: std ``sigma``, correlation time ``tau`` s, sampled every DT."""

    def __init__(self, rng: np.random.Generator, sigma: float, tau: float, size: int):
        self.rng, self.sigma, self.size = rng, sigma, size
        self.decay = float(np.exp(-DT / tau))
        self.value = rng.normal(0.0, sigma, size)

    def step(self) -> np.ndarray:
        innovation = self.rng.normal(0.0, self.sigma * np.sqrt(1.0 - self.decay**2), self.size)
        self.value = self.decay * self.value + innovation
        return self.value


class ExploratoryPilot(Pilot):
    """Goal-seeking PD whose commands are perturbed by Ornstein-Uhlenbeck noise.

    The noise acts where it is physically meaningful: on the commanded acceleration
    (``accel_sigma`` m/s^2, world frame: sustained drifts and near misses), on the commanded
    angular acceleration (``alpha_sigma`` rad/s^2: tumbling) and directly on every thruster
    (``thrust_sigma``, normalised thrust). Raw thrust noise alone would spin the 1U body up
    to hundreds of rad/s (its inertia is 2e-3 kg m^2), so most of it goes through the
    allocator instead. All three share the correlation time ``tau`` seconds.
    """

    level = "exploratory"

    def __init__(self, cruise: float = 1.5, accel_sigma: float = 1.5, alpha_sigma: float = 6.0,
                 thrust_sigma: float = 0.05, tau: float = 0.6, **kwargs):
        super().__init__(**kwargs)
        self.cruise, self.tau = cruise, tau
        self.accel_sigma, self.alpha_sigma, self.thrust_sigma = accel_sigma, alpha_sigma, thrust_sigma

    def reset(self, scenario: Scenario, seed: int) -> None:
        self.goal = np.asarray(scenario.goal, dtype=np.float64)
        self._cruise = max(self.cruise, float(np.linalg.norm(scenario.initial_velocity)))
        rng = make_rng(seed, "pilot")
        self.accel_noise = _OrnsteinUhlenbeck(rng, self.accel_sigma, self.tau, 3)
        self.alpha_noise = _OrnsteinUhlenbeck(rng, self.alpha_sigma, self.tau, 3)
        self.thrust_noise = _OrnsteinUhlenbeck(rng, self.thrust_sigma, self.tau, ACTION_DIM)

    def act(self, state: np.ndarray) -> np.ndarray:
        accel = goal_seeking_accel(self.controller, state, self.goal, self._cruise) + self.accel_noise.step()
        R_des = face(self.controller, state, self.goal - state[0:3])
        nominal = self.controller.thrust(state, accel, R_des, alpha_offset=self.alpha_noise.step())
        return np.clip(nominal + self.thrust_noise.step(), 0.0, 1.0)
