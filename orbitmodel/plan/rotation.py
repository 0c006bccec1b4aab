"""Rotation maths on batched torch tensors, in the dataset's state convention.

``rot6d`` is the first two columns of R (body -> world) stored row-major,
``[R00, R01, R10, R11, R20, R21]`` (``orbitdata.state.matrix_to_rot6d``); rotation vectors are axis *
angle in radians. Every function takes leading batch dimensions.
"""

from __future__ import annotations

import torch


def rot6d_to_matrix(r6: torch.Tensor) -> torch.Tensor:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt; exact for a valid rot6d, nearest rotation otherwise."""
    r = r6.unflatten(-1, (3, 2))  # (..., 3, 2) the two columns
    x = torch.nn.functional.normalize(r[..., 0], dim=-1)
    b = r[..., 1]
    y = torch.nn.functional.normalize(b - (x * b).sum(-1, keepdim=True) * x, dim=-1)
    return torch.stack([x, y, torch.linalg.cross(x, y)], dim=-1)


def matrix_to_rot6d(R: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) -> (..., 6) ``[R00, R01, R10, R11, R20, R21]``."""
    return R[..., :, :2].flatten(-2)


def hat(w: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 3, 3) skew-symmetric matrix with hat(w) @ v = w x v."""
    zero = torch.zeros_like(w[..., 0])
    wx, wy, wz = w.unbind(-1)
    return torch.stack([zero, -wz, wy, wz, zero, -wx, -wy, wx, zero], dim=-1).unflatten(-1, (3, 3))


def so3_exp(phi: torch.Tensor) -> torch.Tensor:
    """Rotation vector (..., 3) radians -> rotation matrix (..., 3, 3) (Rodrigues).

    The series of sin(a)/a and (1 - cos a)/a^2 is used below 1e-3 rad so that small steps
    (w dt is ~1e-2 rad here) keep full float32 precision.
    """
    a2 = (phi * phi).sum(-1, keepdim=True).unsqueeze(-1)  # (..., 1, 1) angle^2
    a = a2.clamp(min=1e-12).sqrt()
    small = a2 < 1e-6
    A = torch.where(small, 1 - a2 / 6, torch.sin(a) / a)
    B = torch.where(small, 0.5 - a2 / 24, (1 - torch.cos(a)) / a2.clamp(min=1e-12))
    K = hat(phi)
    eye = torch.eye(3, dtype=phi.dtype, device=phi.device).expand_as(K)
    return eye + A * K + B * (K @ K)
