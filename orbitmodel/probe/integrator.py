"""Batched rigid-body kinematics for the probe, in torch: rot6d <-> matrix, the so(3)
exponential, the geodesic angle, and the integrator that turns increments into states.

State (16, the dataset's convention): p (3) metres, world frame, relative to the start;
v (3) m/s, body frame; rot6d (6) the first two columns of R (body -> world), row-major
[R00, R01, R10, R11, R20, R21]; w (3) rad/s, body frame; fuel (1) ratio in [0, 1].

Increments (10, what the probe predicts per step): dp (3) metres, world frame; dv (3) m/s,
body frame; dw (3) rad/s, body frame; dfuel (1). One step of ``dt`` seconds::

    p' = p + dp    v' = v + dv    w' = w + dw    R' = GS(R exp(w' dt))    fuel' = clamp(fuel + dfuel, 0, 1)

That is upstream's integrator (``coasting=False``). With ``coasting=True`` zero increments mean
coasting: the world-frame velocity u = R v is held and the position follows it, so the probe
only predicts what thrust and contacts change (and corrections)::

    u' = R v + R' dv    v' = R'^T u'    p' = p + u' dt + dp    (w', R', fuel' as above)

GS is Gram-Schmidt on R's first two columns (what storing rot6d and reading it back does), so R
stays a rotation over any number of steps. Everything runs in float32 with autocast off: a
bf16 rotation drifts off SO(3) within a few steps.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from orbitdata import schema as S
from orbitdata.state import STATE_SLICES

P, V, ROT, W, FUEL = (STATE_SLICES[k] for k in ("p", "v", "r", "w", "fuel"))
INCREMENT_DIM = 10
D_P, D_V, D_W, D_FUEL = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 10)
SMALL_ANGLE = 1e-4  # rad^2: below this, Rodrigues' coefficients come from their Taylor series


def rot6d_to_matrix(rot6d: torch.Tensor) -> torch.Tensor:
    """(..., 6) row-major first two columns -> (..., 3, 3) rotation, by Gram-Schmidt."""
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


def exp_so3(phi: torch.Tensor) -> torch.Tensor:
    """Rotation vector (..., 3) rad -> (..., 3, 3), Rodrigues: I + a K + b K^2 with K = hat(phi),
    a = sin t / t, b = (1 - cos t) / t^2, t = |phi|; exact and smooth through phi = 0."""
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


def _state(p, v, R, w, fuel) -> torch.Tensor:
    return torch.cat([p, v, matrix_to_rot6d(R), w, fuel], dim=-1)


def step(state: torch.Tensor, inc: torch.Tensor, dt: float = S.DT, coasting: bool = False) -> torch.Tensor:
    """One step: state (B, 16), increments (B, 10) -> next state (B, 16)."""
    with torch.autocast(state.device.type, enabled=False):
        state, inc = state.float(), inc.float()
        w = state[..., W] + inc[..., D_W]  # rad/s, body frame
        R0 = rot6d_to_matrix(state[..., ROT])
        R = rot6d_to_matrix(matrix_to_rot6d(R0 @ exp_so3(w * dt)))
        fuel = (state[..., FUEL] + inc[..., D_FUEL]).clamp(0, 1)
        if not coasting:
            return _state(state[..., P] + inc[..., D_P], state[..., V] + inc[..., D_V], R, w, fuel)
        u = _rotate(R0, state[..., V]) + _rotate(R, inc[..., D_V])  # m/s, world frame
        return _state(state[..., P] + u * dt + inc[..., D_P], _rotate(R.transpose(-1, -2), u), R, w, fuel)


def integrate(state0: torch.Tensor, inc: torch.Tensor, dt: float = S.DT, coasting: bool = False) -> torch.Tensor:
    """Roll increments forward: state0 (B, 16), inc (B, n, 10) -> states (B, n, 16), frames 1..n.

    The same maths as n calls of :func:`step`, arranged for the planner's K x H rollouts: the
    additive parts are cumulative sums, every so(3) exponential is one batched call, and the
    attitude is a prefix product in log2(n) batched matmuls, orthonormalised once at the end
    (the per-step Gram-Schmidt of :func:`step` moves a product of rotations by ~1e-7 per step).
    Only the fuel clamp loops over time.
    """
    with torch.autocast(state0.device.type, enabled=False):
        state0, inc = state0.float(), inc.float()
        w = state0[:, None, W] + inc[..., D_W].cumsum(1)  # (B, n, 3) rad/s, body frame
        R0 = rot6d_to_matrix(state0[:, ROT])  # (B, 3, 3)
        R = rot6d_to_matrix(matrix_to_rot6d(R0[:, None] @ prefix_product(exp_so3(w * dt))))  # (B, n, 3, 3)
        if coasting:
            u = _rotate(R0, state0[:, V])[:, None] + _rotate(R, inc[..., D_V]).cumsum(1)  # (B, n, 3) m/s, world
            v = _rotate(R.transpose(-1, -2), u)  # (B, n, 3) m/s, body frame
            p = state0[:, None, P] + (u * dt + inc[..., D_P]).cumsum(1)  # (B, n, 3) metres, world frame
        else:
            v = state0[:, None, V] + inc[..., D_V].cumsum(1)  # (B, n, 3) m/s, body frame
            p = state0[:, None, P] + inc[..., D_P].cumsum(1)  # (B, n, 3) metres, world frame
        fuel, fuels = state0[:, FUEL], []  # (B, 1)
        for k in range(inc.shape[1]):
            fuel = (fuel + inc[:, k, D_FUEL]).clamp(0, 1)
            fuels.append(fuel)
        return _state(p, v, R, w, torch.stack(fuels, 1))


def _rotate(R: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) @ (..., 3) -> (..., 3)."""
    return (R @ x[..., None]).squeeze(-1)


def prefix_product(M: torch.Tensor) -> torch.Tensor:
    """(B, n, 3, 3) -> (B, n, 3, 3) with out[:, k] = M[:, 0] @ ... @ M[:, k] (Hillis-Steele scan)."""
    shift = 1
    while shift < M.shape[1]:
        M = torch.cat([M[:, :shift], M[:, :-shift] @ M[:, shift:]], dim=1)
        shift *= 2
    return M


def increments_of(states: torch.Tensor, dt: float = S.DT, coasting: bool = False) -> torch.Tensor:
    """The increments between consecutive true states: (B, T, 16) -> (B, T-1, 10). Position,
    velocity and rates integrate back exactly; the attitude only as well as exp(w' dt) fits."""
    d = states[:, 1:] - states[:, :-1]
    dp, dv = d[..., P], d[..., V]
    if coasting:  # what coasting does not explain
        R = rot6d_to_matrix(states[..., ROT])  # (B, T, 3, 3)
        u = _rotate(R, states[..., V])  # (B, T, 3) m/s, world frame
        dv = _rotate(R[:, 1:].transpose(-1, -2), u[:, 1:] - u[:, :-1])
        dp = dp - u[:, 1:] * dt
    return torch.cat([dp, dv, d[..., W], d[..., FUEL]], dim=-1)
