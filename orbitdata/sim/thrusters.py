"""Thruster layout and the wrench matrix that maps 8 thrusts to body force and torque."""

from __future__ import annotations

import math

import numpy as np

from orbitdata.sim.config import CubeSatConfig

# Corner sign patterns (sx, sy, sz) in thruster order 0..7.
CORNERS = np.array(
    [
        (+1, +1, +1),
        (-1, +1, +1),
        (-1, -1, +1),
        (+1, -1, +1),
        (+1, +1, -1),
        (-1, +1, -1),
        (-1, -1, -1),
        (+1, -1, -1),
    ],
    dtype=float,
)


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def thruster_layout(cfg: CubeSatConfig) -> tuple[np.ndarray, np.ndarray]:
    """Positions (8, 3) in metres and unit force directions (8, 3), both in the body frame.

    A thruster at corner (sx, sy, sz) exhausts outwards along (0.5 sx, 0.5 sy, sz), so it
    pushes the body along the opposite direction. The exhaust is canted about body z by
    ``cant * sx * sy * sz`` degrees: the sign alternates around each ring, so yaw torque
    is decoupled from heave force (a cant of one sign per ring would tie yaw to z force and
    leave the matrix at rank 5).
    """
    positions = CORNERS * cfg.half_size
    directions = []
    for sx, sy, sz in CORNERS:
        exhaust = np.array([0.5 * sx, 0.5 * sy, sz])
        exhaust = _rot_z(math.radians(cfg.cant_deg) * sx * sy * sz) @ (exhaust / np.linalg.norm(exhaust))
        directions.append(-exhaust)
    return positions, np.array(directions)


def wrench_matrix(cfg: CubeSatConfig, com_offset=None) -> np.ndarray:
    """W (6, 8): [force (N); torque (N m)] in the body frame per unit of normalised thrust.

    Torques are about the centre of mass: the cube's centre, or ``com_offset`` (m, body frame)
    from it (the dynamic tier's body).
    """
    pos, dirs = thruster_layout(cfg)
    if com_offset is not None:
        pos = pos - np.asarray(com_offset, dtype=np.float64)
    force = dirs * cfg.max_thrust  # (8, 3)
    torque = np.cross(pos, force)  # (8, 3) about the centre of mass
    return np.concatenate([force, torque], axis=1).T
