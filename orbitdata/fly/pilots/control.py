"""PD laws for translation and attitude, turned into thrusts through the allocator.

Gains are in natural units (1/s^2, 1/s) on accelerations, then scaled by the current mass and
inertia (from the fuel gauge), so tuning does not change as the tank empties.
"""

from __future__ import annotations

import math

import numpy as np

from orbitdata.fly.pilots.allocation import ThrustAllocator
from orbitdata.fly.pilots.config import ControlGains
from orbitdata.sim.config import CubeSatConfig
from orbitdata.sim.thrusters import wrench_matrix
from orbitdata.state import ANGULAR_VELOCITY, FUEL, POSITION, ROT6D, VELOCITY, cross3, rot6d_to_matrix, so3_log


def look_rotation(forward: np.ndarray, up=(0.0, 0.0, 1.0), fallback: np.ndarray | None = None) -> np.ndarray:
    """Rotation (body->world) whose x axis (the camera axis) is ``forward`` and z is near ``up``."""
    x = np.asarray(forward, dtype=np.float64)
    x = x / math.sqrt(x @ x)
    y = cross3(np.asarray(up, dtype=np.float64), x)
    if math.sqrt(y @ y) < 1e-6:  # looking straight up/down: keep the current heading
        y = fallback[:, 1] if fallback is not None else np.array([0.0, 1.0, 0.0])
        y = y - x * (x @ y)
    y = y / math.sqrt(y @ y)
    return np.column_stack([x, y, cross3(x, y)])


class Controller:
    """Turns (desired world acceleration, desired attitude) into thrusts in [0, 1]."""

    def __init__(self, cubesat: CubeSatConfig = CubeSatConfig(), gains: ControlGains = ControlGains()):
        self.cubesat = cubesat
        self.gains = gains
        self.allocator = ThrustAllocator(wrench_matrix(cubesat), lever_arm=cubesat.half_size)
        self._unpacked: tuple = (None, None)

    def mass_inertia(self, fuel_ratio: float) -> tuple[float, float]:
        return self.cubesat.mass_properties(float(np.clip(fuel_ratio, 0.0, 1.0)) * self.cubesat.fuel_mass)

    def unpack(self, state: np.ndarray):
        """(p world, v world, R body->world, w body, fuel) from a 16-float state.

        Called several times per control step with the same state, so the last result is
        cached (the state array is small; comparing it is cheaper than Gram-Schmidt).
        """
        key = state.tobytes()
        if self._unpacked[0] != key:
            s = state.astype(np.float64)
            R = rot6d_to_matrix(s[ROT6D])
            self._unpacked = (key, (s[POSITION], R @ s[VELOCITY], R, s[ANGULAR_VELOCITY], float(s[FUEL.start])))
        return self._unpacked[1]

    def track_accel(self, state, p_ref, v_ref, a_ff: np.ndarray | None = None) -> np.ndarray:
        """PD acceleration (world, m/s^2) towards a reference position and velocity, plus feed-forward ``a_ff``."""
        p, v, *_ = self.unpack(state)
        g = self.gains
        a_ff = np.zeros(3) if a_ff is None else np.asarray(a_ff)
        a = a_ff + g.pos_kp * (np.asarray(p_ref) - p) + g.pos_kd * (np.asarray(v_ref) - v)
        norm = np.linalg.norm(a)
        return a if norm <= g.max_accel else a * (g.max_accel / norm)

    def thrust(
        self, state: np.ndarray, accel_world: np.ndarray, R_des: np.ndarray, alpha_offset: np.ndarray | None = None
    ) -> np.ndarray:
        """Thrusts that best produce ``accel_world`` while turning towards ``R_des``.

        ``alpha_offset`` (rad/s^2, body frame) is added to the attitude PD's command.
        """
        _, _, R, w, fuel = self.unpack(state)
        mass, inertia = self.mass_inertia(fuel)
        g = self.gains
        err = so3_log(R.T @ R_des)  # body-frame rotation vector to the target attitude
        alpha = g.att_kp * err - g.att_kd * w
        if alpha_offset is not None:
            alpha = alpha + alpha_offset
        norm = np.linalg.norm(alpha)
        if norm > g.max_alpha:
            alpha *= g.max_alpha / norm
        force_body = R.T @ (mass * np.asarray(accel_world))
        wrench = np.concatenate([force_body, inertia * alpha])
        return self.allocator.allocate(wrench)
