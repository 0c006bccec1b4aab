"""SIGReg (LeJEPA, Balestriero & LeCun 2025): push latents towards an isotropic Gaussian.

For random unit directions a, the Epps-Pulley statistic compares the empirical characteristic
function of the projections a.z over N samples with the standard normal's, exp(-t^2/2):

    EP(a) = N * integral_{-3}^{3} |mean_n exp(i t a.z_n) - exp(-t^2/2)|^2 exp(-t^2/2) dt

The integrand is even in t, so the integral is twice the one over [0, 3], taken with the
trapezoid rule on ``knots`` points. SIGReg averages EP over the directions (and here over the
frames of a window: the statistic is computed per frame across the batch, as upstream does).
"""

from __future__ import annotations

import torch


def epps_pulley_weights(knots: int, t_max: float = 3.0, device=None) -> tuple[torch.Tensor, torch.Tensor]:
    """Knots t (K,) and quadrature weights (K,): trapezoid over [0, t_max], doubled, times exp(-t^2/2)."""
    t = torch.linspace(0.0, t_max, knots, device=device)
    dt = t_max / (knots - 1)
    trapezoid = torch.full((knots,), dt, device=device)
    trapezoid[[0, -1]] = dt / 2
    return t, 2 * trapezoid * torch.exp(-t.square() / 2)


def sigreg(
    z: torch.Tensor, projections: int, knots: int = 17, generator: torch.Generator | None = None
) -> torch.Tensor:
    """SIGReg of samples z (..., N, D): the mean Epps-Pulley statistic over ``projections``
    random unit directions (drawn from ``generator``) and over the leading dims."""
    N, D = z.shape[-2:]
    directions = torch.randn(D, projections, generator=generator, device="cpu").to(z.device, z.dtype)
    directions = directions / directions.norm(dim=0, keepdim=True)  # (D, P) unit columns
    t, weights = epps_pulley_weights(knots, device=z.device)
    x = (z @ directions).unsqueeze(-1) * t  # (..., N, P, K)
    phi = torch.exp(-t.square() / 2)  # (K,) characteristic function of N(0, 1)
    err = (torch.cos(x).mean(-3) - phi).square() + torch.sin(x).mean(-3).square()  # (..., P, K)
    return (N * (err @ weights)).mean()
