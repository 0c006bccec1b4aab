"""Exploratory level: strong, temporally correlated random actions around a goal-seeking PD."""

from __future__ import annotations

import numpy as np

from orbitdata.fly.pilot import Task
from orbitdata.fly.pilots.common import ControlledPilot, face, goal_seeking_accel
from orbitdata.fly.pilots.config import ExploratoryConfig
from orbitdata.schema import ACTION_DIM, DT
from orbitdata.seeding import rng as make_rng
from orbitdata.state import POSITION


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


class ExploratoryPilot(ControlledPilot):
    """Goal-seeking PD whose commands are perturbed by Ornstein-Uhlenbeck noise.

    The noise acts where it is physically meaningful: on the commanded acceleration
    (``accel_sigma`` m/s^2, world frame: sustained drifts and near misses), on the commanded
    angular acceleration (``alpha_sigma`` rad/s^2: tumbling) and directly on every thruster
    (``thrust_sigma``, normalised thrust). Raw thrust noise alone would spin the 1U body up
    to hundreds of rad/s (its inertia is 2e-3 kg m^2), so most of it goes through the
    allocator instead. All three share the correlation time ``tau`` seconds.
    """

    name = "exploratory"

    def __init__(self, config: ExploratoryConfig = ExploratoryConfig(), **kwargs):
        super().__init__(**kwargs)
        self.config = config

    def reset(self, task: Task) -> None:
        c = self.config
        self.goal = np.asarray(task.goal, dtype=np.float64)
        self._cruise = max(c.cruise, float(np.linalg.norm(task.initial_velocity)))
        rng = make_rng(task.seed, "pilot")
        self.accel_noise = _OrnsteinUhlenbeck(rng, c.accel_sigma, c.tau, 3)
        self.alpha_noise = _OrnsteinUhlenbeck(rng, c.alpha_sigma, c.tau, 3)
        self.thrust_noise = _OrnsteinUhlenbeck(rng, c.thrust_sigma, c.tau, ACTION_DIM)

    def act(self, obs: dict) -> np.ndarray:
        state = obs["state"]
        accel = goal_seeking_accel(self.controller, state, self.goal, self._cruise) + self.accel_noise.step()
        R_des = face(self.controller, state, self.goal - state[POSITION])
        nominal = self.controller.thrust(state, accel, R_des, alpha_offset=self.alpha_noise.step())
        return np.clip(nominal + self.thrust_noise.step(), 0.0, 1.0)
