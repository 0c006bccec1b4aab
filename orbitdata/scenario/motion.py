"""Analytic motion in the orbital frame: Clohessy-Wiltshire free motion and constant tumble.

The world frame of a dynamic-tier episode is the Hill frame of a reference point on a circular
orbit, placed at the start: x radial (away from the Earth), y along-track (the orbital velocity),
z along the orbit normal. Relative motion there obeys the Clohessy-Wiltshire (Hill) equations
with mean motion n (rad/s)::

    x'' = 3 n^2 x + 2 n y' + f_x / m
    y'' = -2 n x'          + f_y / m
    z'' = -n^2 z           + f_z / m

Free motion (f = 0) has the closed form below, so debris moves exactly and every oracle knows
where it will be; n = 0 is straight-line drift. Rotation is a constant world-frame angular
velocity. Every function takes an array of times and returns one row per time.
"""

from __future__ import annotations

import numpy as np


def cw_acceleration(position, velocity, n) -> np.ndarray:
    """The Clohessy-Wiltshire terms (m/s^2, world frame) at ``position`` (m) and ``velocity`` (m/s):
    (3,) for one point, or (N, 3) for rows of points, each with its own ``n`` ((N,) or one)."""
    p, v = np.asarray(position, dtype=np.float64), np.asarray(velocity, dtype=np.float64)
    x, z, vx, vy = p[..., 0], p[..., 2], v[..., 0], v[..., 1]
    return np.stack([3.0 * n * n * x + 2.0 * n * vy, -2.0 * n * vx, -n * n * z], axis=-1)


def free_motion(p0, v0, times, n: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (T, 3) at ``times`` (T,) s of a free point starting at ``p0`` (m),
    ``v0`` (m/s) at t = 0: the Clohessy-Wiltshire solution, or a straight line when n = 0.
    Negative times run it backwards."""
    t = np.atleast_1d(np.asarray(times, dtype=np.float64))[:, None]  # (T, 1)
    p0, v0 = np.asarray(p0, dtype=np.float64), np.asarray(v0, dtype=np.float64)
    if n == 0.0:
        return p0 + v0 * t, np.broadcast_to(v0, (t.shape[0], 3)).copy()
    x0, y0, z0 = p0
    vx, vy, vz = v0
    nt = n * t[:, 0]
    s, c = np.sin(nt), np.cos(nt)
    position = np.stack(
        [
            (4.0 - 3.0 * c) * x0 + s / n * vx + 2.0 / n * (1.0 - c) * vy,
            6.0 * (s - nt) * x0 + y0 - 2.0 / n * (1.0 - c) * vx + (4.0 * s - 3.0 * nt) / n * vy,
            c * z0 + s / n * vz,
        ],
        axis=1,
    )
    velocity = np.stack(
        [
            3.0 * n * s * x0 + c * vx + 2.0 * s * vy,
            -6.0 * n * (1.0 - c) * x0 - 2.0 * s * vx + (4.0 * c - 3.0) * vy,
            -n * s * z0 + c * vz,
        ],
        axis=1,
    )
    return position, velocity


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) quaternions (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def tumble(q0, omega, times) -> np.ndarray:
    """Attitudes (T, 4) (w, x, y, z) at ``times`` of a body starting at ``q0`` and turning at the
    constant world-frame angular velocity ``omega`` (rad/s): exp(omega t) q0, sign kept w >= 0."""
    t = np.atleast_1d(np.asarray(times, dtype=np.float64))
    omega = np.asarray(omega, dtype=np.float64)
    rate = float(np.linalg.norm(omega))
    half = 0.5 * rate * t  # (T,)
    axis = omega / rate if rate > 0 else np.zeros(3)
    turn = np.concatenate([np.cos(half)[:, None], np.sin(half)[:, None] * axis], axis=1)  # (T, 4)
    q = quat_multiply(turn, np.asarray(q0, dtype=np.float64))
    return np.where(q[:, :1] < 0, -q, q)


def nominal_flight(goal, speed: float, times) -> np.ndarray:
    """Positions (T, 3) of the nominal flight: straight from the start to ``goal`` at ``speed``
    m/s, holding at the goal once there."""
    goal = np.asarray(goal, dtype=np.float64)
    distance = float(np.linalg.norm(goal))
    along = np.minimum(speed * np.atleast_1d(np.asarray(times, dtype=np.float64)), distance)
    return along[:, None] * (goal / distance)
