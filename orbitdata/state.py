"""The 16-float state convention and the rotation maths on it (numpy only: no MuJoCo, no OMPL).

``s_t = [p(3), v(3), r(6), w(3), fuel(1)]`` (the upstream convention):

* ``p``: metres, world frame, relative to the start (p_0 = 0);
* ``v``: m/s, body frame;
* ``r``: rot6d, the first two columns of R (body -> world) stored row-major as
  ``[R00, R01, R10, R11, R20, R21]``;
* ``w``: rad/s, body frame;
* ``fuel``: ratio of a full tank, in [0, 1].

Every function takes leading batch dimensions: rot6d ``(..., 6) <-> (..., 3, 3)``, rotation
vectors ``(..., 3) <-> (..., 3, 3)``. A world model's probe integrates ``p += dp`` and
``R <- R @ so3_exp(w * dt)`` with these.
"""

from __future__ import annotations

import math

import numpy as np

from orbitdata.schema import STATE_DIM

POSITION = slice(0, 3)  # metres, world frame, relative to the start
VELOCITY = slice(3, 6)  # m/s, body frame
ROT6D = slice(6, 12)  # first two columns of R (body->world), row-major
ANGULAR_VELOCITY = slice(12, 15)  # rad/s, body frame
FUEL = slice(15, 16)  # ratio in [0, 1]
STATE_SLICES = {"p": POSITION, "v": VELOCITY, "r": ROT6D, "w": ANGULAR_VELOCITY, "fuel": FUEL}

# Names of the 16 state entries, in order (recorded in meta/info.json).
STATE_NAMES = (
    "p_x",
    "p_y",
    "p_z",
    "v_x",
    "v_y",
    "v_z",
    "r_00",
    "r_01",
    "r_10",
    "r_11",
    "r_20",
    "r_21",
    "w_x",
    "w_y",
    "w_z",
    "fuel",
)
assert len(STATE_NAMES) == STATE_DIM == FUEL.stop


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors; np.cross costs ~40 us on them (axis handling), this ~2 us."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def matrix_to_rot6d(R: np.ndarray) -> np.ndarray:
    """First two columns of R, row-major: (..., 3, 3) -> (..., 6) ``[R00, R01, R10, R11, R20, R21]``."""
    return np.asarray(R)[..., :, :2].reshape(*np.shape(R)[:-2], 6)


def rot6d_to_matrix(r6: np.ndarray) -> np.ndarray:
    """Inverse of :func:`matrix_to_rot6d` by Gram-Schmidt: (..., 6) -> (..., 3, 3) float64.

    Exact for a valid rot6d; any other 6 numbers (a network's output) give the nearest
    rotation in the Gram-Schmidt sense (the first column keeps its direction).
    """
    if np.ndim(r6) == 1:  # one state: the controllers' hot path, without numpy's per-call overhead
        a = np.array([r6[0], r6[2], r6[4]], dtype=np.float64)
        b = np.array([r6[1], r6[3], r6[5]], dtype=np.float64)
        x = a / math.sqrt(a @ a)
        b = b - (x @ b) * x
        y = b / math.sqrt(b @ b)
        return np.column_stack([x, y, cross3(x, y)])
    r6 = np.asarray(r6, dtype=np.float64).reshape(*np.shape(r6)[:-1], 3, 2)
    a, b = r6[..., 0], r6[..., 1]
    x = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b - (x * b).sum(-1, keepdims=True) * x
    y = b / np.linalg.norm(b, axis=-1, keepdims=True)
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-1)


def make_state(p: np.ndarray, v_body: np.ndarray, R: np.ndarray, w_body: np.ndarray, fuel: float) -> np.ndarray:
    """Assemble s_t = [p(3), v(3), rot6d(6), w(3), fuel(1)] as float32 (16,)."""
    s = np.empty(STATE_DIM, dtype=np.float32)
    s[POSITION] = p
    s[VELOCITY] = v_body
    s[ROT6D] = matrix_to_rot6d(R)
    s[ANGULAR_VELOCITY] = w_body
    s[FUEL] = fuel
    return s


def quat_to_matrix(quat) -> np.ndarray:
    """(w, x, y, z) unit quaternion -> 3x3 rotation matrix (body -> world)."""
    w, x, y, z = (float(q) for q in quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def so3_exp(rotvec: np.ndarray) -> np.ndarray:
    """Rotation vectors (axis * angle, radians) -> rotation matrices (Rodrigues): (..., 3) -> (..., 3, 3)."""
    rv = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(rv, axis=-1)  # (...,)
    k = rv / np.maximum(theta, 1e-300)[..., None]  # unit axis; 0 for a zero rotation
    K = np.zeros((*rv.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    s = np.sin(theta)[..., None, None]
    c = (1.0 - np.cos(theta))[..., None, None]
    return np.eye(3) + s * K + c * (K @ K)


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation matrices -> rotation vectors (axis * angle, angle in [0, pi]): (..., 3, 3) -> (..., 3)."""
    R = np.asarray(R)
    if R.ndim == 2:  # one matrix: the attitude controller's hot path
        cos = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
        angle = np.arccos(cos)
        vee = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
        if angle < 1e-6:
            return 0.5 * vee
        if np.pi - angle < 1e-4:
            # Near pi the antisymmetric part vanishes; take the axis from the symmetric part.
            k = int(np.argmax(np.diag(R)))
            axis = (R[:, k] + np.eye(3)[k]) / np.sqrt(2.0 * (1.0 + R[k, k]))
            return angle * axis
        return angle / (2.0 * np.sin(angle)) * vee
    R = R.astype(np.float64)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)[..., None]  # (..., 1)
    vee = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(angle < 1e-6, 0.5 * vee, angle / (2.0 * np.sin(angle)) * vee)
        diag = np.diagonal(R, axis1=-2, axis2=-1)  # (..., 3)
        k = np.argmax(diag, axis=-1)[..., None]  # (..., 1)
        column = np.take_along_axis(R, k[..., None, :], axis=-1)[..., 0]  # (..., 3) = R[..., :, k]
        axis = (column + (np.arange(3) == k)) / np.sqrt(2.0 * (1.0 + np.take_along_axis(diag, k, -1)))
    return np.where(np.pi - angle < 1e-4, angle * axis, out)
