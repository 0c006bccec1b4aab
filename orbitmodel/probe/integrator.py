"""The probe's integrator: per-step increments -> states, batched in torch (the rotation maths
and the state layout are ``orbitmodel.kinematics``').

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

from orbitdata import schema as S
from orbitmodel.kinematics import FUEL, ROT, P, V, W, matrix_to_rot6d, rot6d_to_matrix, rotate, so3_exp

INCREMENT_DIM = 10
D_P, D_V, D_W, D_FUEL = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 10)


def _state(p, v, R, w, fuel) -> torch.Tensor:
    return torch.cat([p, v, matrix_to_rot6d(R), w, fuel], dim=-1)


def step(state: torch.Tensor, inc: torch.Tensor, dt: float = S.DT, coasting: bool = False) -> torch.Tensor:
    """One step: state (B, 16), increments (B, 10) -> next state (B, 16)."""
    with torch.autocast(state.device.type, enabled=False):
        state, inc = state.float(), inc.float()
        w = state[..., W] + inc[..., D_W]  # rad/s, body frame
        R0 = rot6d_to_matrix(state[..., ROT])
        R = rot6d_to_matrix(matrix_to_rot6d(R0 @ so3_exp(w * dt)))
        fuel = (state[..., FUEL] + inc[..., D_FUEL]).clamp(0, 1)
        if not coasting:
            return _state(state[..., P] + inc[..., D_P], state[..., V] + inc[..., D_V], R, w, fuel)
        u = rotate(R0, state[..., V]) + rotate(R, inc[..., D_V])  # m/s, world frame
        return _state(state[..., P] + u * dt + inc[..., D_P], rotate(R.transpose(-1, -2), u), R, w, fuel)


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
        R = rot6d_to_matrix(matrix_to_rot6d(R0[:, None] @ prefix_product(so3_exp(w * dt))))  # (B, n, 3, 3)
        if coasting:
            u = rotate(R0, state0[:, V])[:, None] + rotate(R, inc[..., D_V]).cumsum(1)  # (B, n, 3) m/s, world
            v = rotate(R.transpose(-1, -2), u)  # (B, n, 3) m/s, body frame
            p = state0[:, None, P] + (u * dt + inc[..., D_P]).cumsum(1)  # (B, n, 3) metres, world frame
        else:
            v = state0[:, None, V] + inc[..., D_V].cumsum(1)  # (B, n, 3) m/s, body frame
            p = state0[:, None, P] + inc[..., D_P].cumsum(1)  # (B, n, 3) metres, world frame
        fuel, fuels = state0[:, FUEL], []  # (B, 1)
        for k in range(inc.shape[1]):
            fuel = (fuel + inc[:, k, D_FUEL]).clamp(0, 1)
            fuels.append(fuel)
        return _state(p, v, R, w, torch.stack(fuels, 1))


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
        u = rotate(R, states[..., V])  # (B, T, 3) m/s, world frame
        dv = rotate(R[:, 1:].transpose(-1, -2), u[:, 1:] - u[:, :-1])
        dp = dp - u[:, 1:] * dt
    return torch.cat([dp, dv, d[..., W], d[..., FUEL]], dim=-1)
