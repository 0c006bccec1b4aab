"""The 16-float state convention and rotation helpers."""

from __future__ import annotations

import math

import numpy as np

from orbitdata.schema import STATE_DIM


def rot6d(R: np.ndarray) -> np.ndarray:
    """First two columns of R (body->world), row-major: [R00, R01, R10, R11, R20, R21]."""
    return np.asarray(R)[..., :, :2].reshape(*np.shape(R)[:-2], 6)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors; np.cross costs ~40 us on them (axis handling), this ~2 us."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def rot6d_to_matrix(r6: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rot6d` by Gram-Schmidt (exact for a valid rot6d); (..., 6) -> (..., 3, 3)."""
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
    """Assemble s_t = [p(3), v(3), rot6d(6), w(3), fuel(1)] as float32."""
    s = np.empty(STATE_DIM, dtype=np.float32)
    s[0:3] = p
    s[3:6] = v_body
    s[6:12] = rot6d(R)
    s[12:15] = w_body
    s[15] = fuel
    return s


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, radians) of a rotation matrix."""
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
