"""Model Predictive Path Integral control (Williams et al. 2017) over thrust sequences, batched.

Each replan perturbs the nominal sequence U (H, 8) with K Gaussian draws, clips them to the
thrust box [0, 1], scores them with a cost callable and moves U to their softmin-weighted mean::

    A_k = clip(U + eps_k, 0, 1),  eps_k ~ N(0, S S^T) per step, AR(1)-smoothed along the horizon
    w_k = softmax(-(c(A_k) - min c) / lambda)
    U  <- sum_k w_k A_k

The mean of clipped candidates stays inside the box, so U is always a valid command. Candidate
0 is U itself (noise-free), so a replan never discards a plan that was already best. After the
first action is executed, :meth:`MPPI.shift` advances U by one step (warm start).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

# cost(actions (K, H, A)) -> (K,) lower is better; a non-finite cost gets no weight.
CostFn = Callable[[torch.Tensor], torch.Tensor]


@dataclass(frozen=True)
class MPPIConfig:
    """Sampling and weighting.

    Args:
        samples: K candidate sequences per iteration (the paper: 256).
        horizon: H control steps of 0.04 s (the paper: 50, i.e. 2 s).
        iterations: sample-and-reweight rounds per replan.
        noise_std: standard deviation of each perturbation coordinate, in thrust units
            (per thruster, or per column of a noise basis, see :class:`MPPI`).
        smoothing: AR(1) coefficient in [0, 1) of the noise along the horizon; the marginal
            std stays ``noise_std`` (0: white noise; 0.9: about 10 steps of correlation).
        temperature: lambda of the softmin weights, in units of the cost.
        shift_fill: what enters the end of U when it shifts: "zero" (coast) or "last" (hold).
    """

    samples: int = 256
    horizon: int = 50
    iterations: int = 1
    noise_std: float = 0.15
    smoothing: float = 0.8
    temperature: float = 1.0
    shift_fill: str = "zero"

    def __post_init__(self):
        for key, least in (("samples", 2), ("horizon", 1), ("iterations", 1)):
            if getattr(self, key) < least:
                raise ValueError(f"{key}={getattr(self, key)} must be >= {least} (MPPI)")
        if not self.noise_std > 0 or not self.temperature > 0:
            raise ValueError(f"noise_std={self.noise_std} and temperature={self.temperature} must be > 0")
        if not 0 <= self.smoothing < 1:
            raise ValueError(f"smoothing={self.smoothing} must be in [0, 1)")
        if self.shift_fill not in ("zero", "last"):
            raise ValueError(f"shift_fill={self.shift_fill!r}: use 'zero' or 'last'")


@dataclass
class PlanResult:
    """One replan: the new nominal and what its last iteration saw."""

    nominal: torch.Tensor  # (H, A) thrust in [0,1]: U after the update
    candidates: torch.Tensor  # (K, H, A) the last iteration's clipped samples
    costs: torch.Tensor  # (K,) their costs, as the cost callable returned them
    weights: torch.Tensor  # (K,) their softmin weights
    best: int  # index of the cheapest candidate

    @property
    def action(self) -> torch.Tensor:
        """(A,) the first step of the nominal: what to execute now."""
        return self.nominal[0]

    @property
    def effective_samples(self) -> float:
        """1 / sum w^2: how many candidates the update really averaged."""
        return float(1.0 / (self.weights**2).sum())


class MPPI:
    """The sampler and its warm-started nominal sequence.

    ``noise_basis`` (A, r), optional: perturbations are ``noise_basis @ n`` with n ~ N(0,
    noise_std^2 I_r), a Gaussian with covariance ``noise_std^2 B B^T`` (e.g. thrust patterns
    that produce independent forces and torques); default: independent per action coordinate.
    """

    def __init__(
        self,
        config: MPPIConfig = MPPIConfig(),
        action_dim: int = 8,
        noise_basis: torch.Tensor | None = None,
        low: float = 0.0,
        high: float = 1.0,
    ):
        self.config = config
        self.action_dim = action_dim
        if noise_basis is not None and (noise_basis.ndim != 2 or noise_basis.shape[0] != action_dim):
            raise ValueError(f"noise_basis must be ({action_dim}, r), got {tuple(noise_basis.shape)}")
        self.basis = None if noise_basis is None else noise_basis.float()
        self.low, self.high = low, high
        self.reset()

    def reset(self, nominal: torch.Tensor | None = None) -> None:
        """Start a new episode from ``nominal`` (H, A), default all zero (coast)."""
        H, A = self.config.horizon, self.action_dim
        self.nominal = torch.zeros(H, A) if nominal is None else nominal.float().clamp(self.low, self.high).clone()

    def shift(self) -> None:
        """Drop the executed first step and extend the end (``shift_fill``)."""
        fill = torch.zeros_like(self.nominal[-1:]) if self.config.shift_fill == "zero" else self.nominal[-1:]
        self.nominal = torch.cat([self.nominal[1:], fill], 0)

    def sample_noise(self, generator: torch.Generator) -> torch.Tensor:
        """(K, H, A) perturbations: Gaussian, AR(1) along the horizon, row 0 zero."""
        c = self.config
        r = self.action_dim if self.basis is None else self.basis.shape[1]
        white = torch.randn(c.samples, c.horizon, r, generator=generator) * c.noise_std  # (K, H, r)
        if c.smoothing > 0:
            a, b = c.smoothing, (1 - c.smoothing**2) ** 0.5
            steps = [white[:, 0]]
            for t in range(1, c.horizon):
                steps.append(a * steps[-1] + b * white[:, t])
            white = torch.stack(steps, 1)
        noise = white if self.basis is None else white @ self.basis.T  # (K, H, A)
        noise[0] = 0.0
        return noise

    @torch.inference_mode()
    def optimize(self, cost: CostFn, generator: torch.Generator) -> PlanResult:
        """Run ``iterations`` sample-and-reweight rounds on the nominal and return the result."""
        result = None
        for _ in range(self.config.iterations):
            candidates = self.propose(generator)
            result = self.update(candidates, cost(candidates))
        return result

    def propose(self, generator: torch.Generator) -> torch.Tensor:
        """(K, H, A) candidates of one round: the nominal perturbed by draws of ``generator``, clipped."""
        return (self.nominal[None] + self.sample_noise(generator)).clamp(self.low, self.high)  # (K, H, A)

    @torch.inference_mode()
    def update(self, candidates: torch.Tensor, costs: torch.Tensor) -> PlanResult:
        """Move the nominal to the softmin-weighted mean of ``candidates`` (K, H, A) by their ``costs`` (K,).
        :meth:`optimize` is propose, cost, update; the lockstep flights cost many episodes' candidates
        in one call between the two (``plan.batch``)."""
        costs = costs.float()  # (K,)
        if costs.shape != (len(candidates),):
            raise ValueError(f"the cost returned shape {tuple(costs.shape)}; expected ({len(candidates)},)")
        # A non-finite cost (a diverged model) gets no weight; if all are, U stays the plain mean.
        finite = torch.isfinite(costs)
        ranked = torch.where(finite, costs, torch.inf)  # (K,)
        logits = -(ranked - ranked.min()) / self.config.temperature if finite.any() else torch.zeros_like(costs)
        weights = torch.softmax(logits, 0)  # (K,)
        self.nominal = (weights[:, None, None] * candidates).sum(0)  # (H, A) inside the box
        return PlanResult(self.nominal, candidates, costs, weights, int(ranked.argmin()))
