"""Thrust allocation: a body wrench -> 8 thrusts in [0, 1] by bounded least squares."""

from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear, nnls


class ThrustAllocator:
    """Maps a desired body-frame wrench [F (N), tau (N m)] to normalised thrusts.

    Torque rows are divided by the lever arm so that newtons and newton-metres weigh alike
    in the least-squares fit. An achievable wrench is reproduced exactly (non-negative least
    squares first, which also favours few active thrusters); one outside the thrust box gets
    the bounded least-squares best fit, i.e. the closest achievable wrench.
    """

    def __init__(self, wrench_matrix: np.ndarray, lever_arm: float):
        if wrench_matrix.shape[0] != 6:
            raise ValueError(f"wrench matrix must be (6, n), got {wrench_matrix.shape}")
        self.W = np.asarray(wrench_matrix, dtype=np.float64)
        self._scale = np.array([1.0, 1.0, 1.0, 1 / lever_arm, 1 / lever_arm, 1 / lever_arm])
        self._Ws = self._scale[:, None] * self.W

    def allocate(self, wrench: np.ndarray) -> np.ndarray:
        """(6,) body wrench -> (n,) thrusts in [0, 1]."""
        target = self._scale * np.asarray(wrench, dtype=np.float64)
        u, _ = nnls(self._Ws, target)
        if u.max() > 1.0:
            u = lsq_linear(self._Ws, target, bounds=(0.0, 1.0), method="bvls").x
        return np.clip(u, 0.0, 1.0)

    def wrench(self, thrust: np.ndarray) -> np.ndarray:
        """The body wrench (6,) that thrusts (n,) produce."""
        return self.W @ np.asarray(thrust, dtype=np.float64)
