"""Hand-made scenes and thrust helpers for simulator tests."""

import numpy as np

from orbitdata.scenario.spec import Lighting, Obstacle, Scenario


def pure_force_thrust(env, force_body) -> np.ndarray:
    """Thrusts (8,) giving exactly ``force_body`` (N) with zero torque."""
    from orbitdata.fly.pilots.allocation import ThrustAllocator

    u = ThrustAllocator(env.wrench_matrix, 0.05).allocate(np.r_[force_body, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(env.wrench_matrix @ u, np.r_[force_body, 0, 0, 0], atol=1e-9)
    return u


def free_space(velocity=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0), goal=(50.0, 0.0, 0.0)) -> Scenario:
    """No obstacles, a far goal: nothing ends the episode early."""
    return Scenario(obstacles=(), goal=goal, initial_velocity=velocity, initial_quat=quat, lighting=Lighting())


def wall_ahead(distance: float = 1.0) -> Scenario:
    """A big box across the +x axis, ``distance`` m ahead of the hull's front face."""
    box = Obstacle("box", center=(0.05 + distance + 0.5, 0.0, 0.0), size=(0.5, 2.0, 2.0))
    return Scenario(obstacles=(box,), goal=(0.0, 0.0, 10.0), initial_velocity=(2.0, 0.0, 0.0))
