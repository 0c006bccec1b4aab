"""MPPI: converges on a known cost, respects the thrust box, survives bad costs, reproducible."""

from __future__ import annotations

import torch

from orbitmodel.plan.mppi import MPPI, MPPIConfig

torch.set_num_threads(1)  # small batched ops: one thread is fastest, and the machine is shared


def quadratic(target: torch.Tensor):
    return lambda a: ((a - target) ** 2).sum((1, 2))  # (K, H, A) -> (K,)


def converge(target: torch.Tensor, rounds: int = 60, smoothing: float = 0.0) -> MPPI:
    # A temperature that keeps ~150 of 256 samples effective: each round is then close to a
    # gradient step of size noise_std^2 / temperature (0.05 of the way), with little noise.
    H, A = target.shape
    mppi = MPPI(MPPIConfig(samples=256, horizon=H, noise_std=0.1, temperature=0.2, smoothing=smoothing), action_dim=A)
    g = torch.Generator().manual_seed(0)
    for _ in range(rounds):
        mppi.optimize(quadratic(target), g)
    return mppi


def test_converges_to_the_minimum_of_a_quadratic():
    target = torch.rand(6, 8, generator=torch.Generator().manual_seed(1)) * 0.6 + 0.2  # (H, 8) inside the box
    mppi = converge(target)
    assert (mppi.nominal - target).abs().max() < 0.05


def test_smoothed_noise_converges_too():
    target = torch.full((10, 8), 0.4)
    mppi = converge(target, smoothing=0.6)
    assert (mppi.nominal - target).abs().max() < 0.05


def test_box_constrained_minimum_is_the_clipped_target():
    target = torch.tensor([[-0.5, 1.5, 0.3, 0.7]] * 4)  # two coordinates outside [0, 1]
    mppi = converge(target)
    assert (mppi.nominal - target.clamp(0, 1)).abs().max() < 0.05
    assert mppi.nominal.min() >= 0 and mppi.nominal.max() <= 1


def test_non_finite_costs_never_reach_the_nominal():
    mppi = MPPI(MPPIConfig(samples=16, horizon=5))
    g = torch.Generator().manual_seed(0)
    result = mppi.optimize(lambda a: torch.full((len(a),), float("nan")), g)
    assert torch.isfinite(result.nominal).all() and result.nominal.min() >= 0 and result.nominal.max() <= 1
    bad_half = lambda a: torch.where(torch.arange(len(a)) % 2 == 0, torch.inf, a.sum((1, 2)))  # noqa: E731
    result = mppi.optimize(bad_half, g)
    assert torch.isfinite(result.nominal).all()
    assert result.weights[::2].max() < 1e-6  # the infinite-cost candidates get no weight


def test_same_generator_seed_same_plan():
    target = torch.full((5, 8), 0.5)
    plans = []
    for _ in range(2):
        mppi = MPPI(MPPIConfig(samples=32, horizon=5))
        plans.append(mppi.optimize(quadratic(target), torch.Generator().manual_seed(7)).nominal)
    assert torch.equal(plans[0], plans[1])


def test_candidate_zero_is_the_nominal_and_shift_warm_starts():
    mppi = MPPI(MPPIConfig(samples=8, horizon=4, shift_fill="zero"))
    nominal = torch.linspace(0, 1, 4)[:, None].expand(4, 8)
    mppi.reset(nominal)
    result = mppi.optimize(lambda a: a.sum((1, 2)), torch.Generator().manual_seed(0))
    assert torch.equal(result.candidates[0], nominal)
    before = mppi.nominal.clone()
    mppi.shift()
    assert torch.equal(mppi.nominal[:-1], before[1:]) and mppi.nominal[-1].abs().max() == 0


def test_noise_basis_shapes_the_perturbations():
    basis = torch.zeros(8, 2)
    basis[0, 0] = basis[1, 1] = 1.0  # only thrusters 0 and 1 move
    mppi = MPPI(MPPIConfig(samples=64, horizon=3), noise_basis=basis)
    noise = mppi.sample_noise(torch.Generator().manual_seed(0))
    assert noise.shape == (64, 3, 8)
    assert noise[..., 2:].abs().max() == 0 and noise[1:, :, :2].std() > 0.05
