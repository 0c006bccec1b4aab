"""Thrust noise on any pilot: what accuracy a given chunk length needs (the sanity ladder).

:class:`ThrustNoise` wraps a pilot and adds Gaussian noise of ``sigma`` (normalised thrust) to
every action it takes, clipped to [0, 1]: redrawn every control step (``hold`` 1), or held for
``hold`` steps at a time, as the error of an action chunk executed open loop would be. The noise
comes from the episode seed's own stream, so an episode is reproducible.

    orbitdata fly --pilot expert --thrust-noise 0.05 --noise-hold 8
"""

from __future__ import annotations

import numpy as np

from orbitdata.fly.pilot import Pilot
from orbitdata.schema import ACTION_DIM
from orbitdata.seeding import rng


class ThrustNoise(Pilot):
    """``pilot``'s actions plus N(0, sigma^2) per thruster, redrawn every ``hold`` control steps."""

    def __init__(self, pilot: Pilot, sigma: float, hold: int = 1):
        if not sigma >= 0 or hold < 1:
            raise ValueError(f"thrust noise sigma={sigma}, hold={hold}: give sigma >= 0 and hold >= 1 control steps")
        self.pilot, self.sigma, self.hold = pilot, float(sigma), int(hold)
        self.name = f"{pilot.name}+noise{sigma:g}x{hold}"
        self.privileged, self.needs_images = pilot.privileged, pilot.needs_images
        self.sees_depth = getattr(pilot, "sees_depth", False)
        self._rng, self._noise, self._t = rng(0, "thrust-noise"), np.zeros(ACTION_DIM), 0

    def reset(self, task, **kwargs) -> None:
        self.pilot.reset(task, **kwargs)
        self._rng, self._t = rng(int(task.seed), "thrust-noise"), 0

    def act(self, obs: dict) -> np.ndarray:
        if self._t % self.hold == 0:
            self._noise = self._rng.normal(0.0, self.sigma, ACTION_DIM)
        self._t += 1
        return np.clip(np.asarray(self.pilot.act(obs), dtype=np.float64) + self._noise, 0.0, 1.0)

    def metadata(self) -> dict:
        return {**self.pilot.metadata(), "thrust_noise": self.sigma, "noise_hold": self.hold}
