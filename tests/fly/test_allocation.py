"""Thrust allocation reproduces achievable wrenches and saturates sensibly otherwise."""

import numpy as np
import pytest

from orbitdata.fly.pilots.allocation import ThrustAllocator
from orbitdata.sim import CubeSatConfig, wrench_matrix


@pytest.fixture(scope="module")
def allocator():
    return ThrustAllocator(wrench_matrix(CubeSatConfig()), lever_arm=0.05)


def test_achievable_wrenches_are_reproduced_exactly(allocator):
    rng = np.random.default_rng(0)
    for _ in range(500):
        target = allocator.W @ rng.uniform(0, 1, 8)  # achievable by construction
        u = allocator.allocate(target)
        assert u.min() >= 0 and u.max() <= 1
        np.testing.assert_allclose(allocator.wrench(u), target, atol=1e-8)


def test_every_direction_is_achievable_at_small_magnitude(allocator):
    rng = np.random.default_rng(1)
    for _ in range(200):
        d = rng.normal(size=6)
        target = 0.05 * d / np.linalg.norm(d) * np.array([1, 1, 1, 0.05, 0.05, 0.05])
        np.testing.assert_allclose(allocator.wrench(allocator.allocate(target)), target, atol=1e-9)


def test_unachievable_wrench_saturates_to_the_closest_achievable(allocator):
    huge = np.array([500.0, 0, 0, 0, 0, 0])  # far beyond 8 x 5 N
    u = allocator.allocate(huge)
    assert u.min() >= 0 and u.max() <= 1 + 1e-12
    w = allocator.wrench(u)
    assert w[0] > 5  # pushes as hard as it can the right way
    # ...and no achievable wrench is closer in the scaled metric (check against random ones).
    scale = np.array([1, 1, 1, 20, 20, 20])
    best = np.linalg.norm(scale * (w - huge))
    rng = np.random.default_rng(2)
    others = np.linalg.norm(scale * ((allocator.W @ rng.uniform(0, 1, (8, 5000))).T - huge), axis=1)
    assert best <= others.min() + 1e-6


def test_zero_wrench_gives_zero_thrust(allocator):
    np.testing.assert_array_equal(allocator.allocate(np.zeros(6)), np.zeros(8))
