"""Rigid-body maths on batched torch tensors, in the dataset's state convention (``orbitdata.state``).

State (16): p (3) metres, world frame, relative to the start; v (3) m/s, body frame; rot6d (6)
the first two columns of R (body -> world) stored row-major ``[R00, R01, R10, R11, R20, R21]``;
w (3) rad/s, body frame; fuel (1) ratio in [0, 1]. Rotation vectors are axis * angle in radians.
Every function takes leading batch dimensions. The slices and the physical constants are
orbitdata's, imported, never copied: the numpy twins of these functions live in ``orbitdata.state``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from orbitdata.sim.config import G0, CubeSatConfig
from orbitdata.state import STATE_SLICES

P, V, ROT, W, FUEL = (STATE_SLICES[k] for k in ("p", "v", "r", "w", "fuel"))
HULL_RADIUS = CubeSatConfig().bounding_radius  # metres: the bounding sphere of the 1U hull
SMALL_ANGLE = 1e-4  # rad^2: below this, Rodrigues' coefficients come from their Taylor series

__all__ = [
    "P",
    "V",
    "ROT",
    "W",
    "FUEL",
    "G0",
    "HULL_RADIUS",
    "rot6d_to_matrix",
    "matrix_to_rot6d",
    "hat",
    "so3_exp",
    "geodesic_angle",
    "rotate",
    "body_to_world",
    "interpolate_frames",
]


def rot6d_to_matrix(rot6d: torch.Tensor) -> torch.Tensor:
    """(..., 6) row-major first two columns -> (..., 3, 3) rotation by Gram-Schmidt; exact for a
    valid rot6d, the nearest rotation of that construction otherwise."""
    cols = rot6d.unflatten(-1, (3, 2))  # (..., 3, 2): row i holds [R_i0, R_i1]
    b1 = F.normalize(cols[..., 0], dim=-1)  # (..., 3)
    a2 = cols[..., 1]
    b2 = F.normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1, dim=-1)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-1)  # columns b1, b2, b3


def matrix_to_rot6d(R: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) -> (..., 6) = R[..., :, :2] row-major."""
    return R[..., :2].flatten(-2)


def hat(w: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 3, 3) skew matrix with hat(w) x = w x x."""
    x, y, z = w.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).unflatten(-1, (3, 3))


def so3_exp(phi: torch.Tensor) -> torch.Tensor:
    """Rotation vector (..., 3) rad -> (..., 3, 3), Rodrigues: I + a K + b K^2 with K = hat(phi),
    a = sin t / t, b = (1 - cos t) / t^2, t = |phi|; below ``SMALL_ANGLE`` both come from their
    series, so the small steps of a control period (w dt ~ 1e-2 rad) keep float32 precision."""
    t2 = (phi * phi).sum(-1)[..., None, None]  # (..., 1, 1)
    small = t2 < SMALL_ANGLE
    t2_safe = torch.where(small, torch.ones_like(t2), t2)
    t = t2_safe.sqrt()
    a = torch.where(small, 1 - t2 / 6 + t2 * t2 / 120, torch.sin(t) / t)
    b = torch.where(small, 0.5 - t2 / 24 + t2 * t2 / 720, (1 - torch.cos(t)) / t2_safe)
    K = hat(phi)
    eye = torch.eye(3, dtype=phi.dtype, device=phi.device)
    return eye + a * K + b * (K @ K)


def geodesic_angle(R_a: torch.Tensor, R_b: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) x 2 -> (...) rad in [0, pi]: the angle of R_a^T R_b. atan2 of the sine (from
    the skew part) and the cosine (from the trace) keeps it accurate near 0, where acos is not."""
    E = R_a.transpose(-1, -2) @ R_b
    cos = (E.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    skew = torch.stack([E[..., 2, 1] - E[..., 1, 2], E[..., 0, 2] - E[..., 2, 0], E[..., 1, 0] - E[..., 0, 1]], -1)
    return torch.atan2(skew.norm(dim=-1) / 2, cos)


def rotate(R: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) @ (..., 3) -> (..., 3)."""
    return (R @ x[..., None]).squeeze(-1)


def body_to_world(states: torch.Tensor) -> torch.Tensor:
    """R (..., 3, 3), body -> world, of states (..., 16)."""
    return rot6d_to_matrix(states[..., ROT])


def interpolate_frames(state0: torch.Tensor, states: torch.Tensor, step: int) -> torch.Tensor:
    """States every ``step`` frames -> every frame, linearly: state0 (K, 16) at frame t and states
    (K, n, 16) at t+step, ..., t+n step -> (K, n step, 16) at t+1..t+n step. The attitude columns
    are interpolated too and re-orthonormalised (how the planner and ``eval probe`` read a world
    model that steps several frames per prediction)."""
    knots = torch.cat([state0[:, None], states], 1)  # (K, n+1, 16)
    frac = torch.arange(1, step + 1, dtype=states.dtype, device=states.device) / step  # (step,)
    a, b = knots[:, :-1, None], knots[:, 1:, None]  # (K, n, 1, 16)
    out = (a + (b - a) * frac[:, None]).flatten(1, 2)  # (K, n step, 16)
    return torch.cat([out[..., : ROT.start], matrix_to_rot6d(rot6d_to_matrix(out[..., ROT])), out[..., ROT.stop :]], -1)
