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


def state_at(position) -> np.ndarray:
    """(16,) state at ``position`` (m), at rest, identity attitude (the camera looks along +x)."""
    return np.r_[position, np.zeros(3), 1, 0, 0, 1, 0, 0, np.zeros(3), 1].astype(np.float32)


def sphere_depth(camera, position, spheres) -> np.ndarray:
    """(16, 16) z-depth (m) of ``spheres`` [(centre, radius)] seen through ``camera`` (the planner's
    ``Camera``) from a body at ``position`` with identity attitude: each cell's ray cast exactly;
    the far plane where it meets none."""
    rays = camera.cell_rays()  # (16, 16, 3) body = world here, unit z-depth
    origin = np.asarray(position, float) + np.asarray(camera.position)
    depth = np.full(rays.shape[:2], camera.far)
    for centre, radius in spheres:
        oc = origin - np.asarray(centre, float)
        a, b, c = (rays * rays).sum(-1), (rays * oc).sum(-1), oc @ oc - radius**2
        disc = b * b - a * c
        s = (-b - np.sqrt(np.maximum(disc, 0))) / a
        depth = np.where((disc >= 0) & (s > 0) & (s < depth), s, depth)
    return depth
