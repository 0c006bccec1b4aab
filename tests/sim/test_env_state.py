"""The env keeps the 16-float state convention: p_0 = 0, body-frame velocities, rot6d, kinematics."""

import numpy as np
from scenes import free_space

from orbitdata.state import quat_to_matrix, rot6d_to_matrix


def test_initial_state_is_at_origin_with_body_frame_velocity(physics_env):
    # Yaw by 90 deg: body x points along world y. A world +y velocity is body +x.
    q = (np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4))
    obs, _ = physics_env.reset(options={"scenario": free_space(velocity=(0.0, 1.5, 0.0), quat=q)})
    s = obs["state"]
    assert s.dtype == np.float32 and s.shape == (16,)
    np.testing.assert_array_equal(s[0:3], 0.0)
    np.testing.assert_allclose(s[3:6], [1.5, 0.0, 0.0], atol=1e-6)
    R = quat_to_matrix(q)
    np.testing.assert_allclose(s[6:12], [R[0, 0], R[0, 1], R[1, 0], R[1, 1], R[2, 0], R[2, 1]], atol=1e-6)
    assert s[15] == 1.0


def test_position_increment_matches_rotated_body_velocity(physics_env):
    rng = np.random.default_rng(0)
    obs, _ = physics_env.reset(options={"scenario": free_space(velocity=(1.0, -0.5, 0.3))})
    dt = physics_env.sim.dt
    states = [obs["state"]]
    for _ in range(60):
        obs, *_ = physics_env.step(rng.uniform(0, 0.3, 8))
        states.append(obs["state"])
    s = np.array(states, dtype=np.float64)
    R = rot6d_to_matrix(s[:, 6:12])
    v_world = np.einsum("tij,tj->ti", R, s[:, 3:6])
    dp = s[1:, 0:3] - s[:-1, 0:3]
    trapezoid = 0.5 * (v_world[1:] + v_world[:-1]) * dt
    # Thrust is constant within a step, so the trapezoid rule is second order: mm accuracy.
    np.testing.assert_allclose(dp, trapezoid, atol=2e-3)
    # ...and the body-frame convention matters: using v_body as if it were world frame fails.
    wrong = 0.5 * (s[1:, 3:6] + s[:-1, 3:6]) * dt
    assert np.abs(dp - wrong).max() > 5 * np.abs(dp - trapezoid).max()


def test_angular_velocity_is_body_frame(physics_env):
    obs, _ = physics_env.reset(options={"scenario": free_space()})
    # Fire a pure body-yaw torque for one step, then coast.
    W = physics_env.wrench_matrix
    from orbitdata.fly.pilots.allocation import ThrustAllocator

    u = ThrustAllocator(W, 0.05).allocate(np.array([0, 0, 0, 0, 0, 0.01]))
    obs, *_ = physics_env.step(u)
    states = [obs["state"]]
    for _ in range(10):
        obs, *_ = physics_env.step(np.zeros(8))
        states.append(obs["state"])
    s = np.array(states, dtype=np.float64)
    w = s[:, 12:15]
    assert abs(w[0, 2]) > 0.1 and np.abs(w[0, :2]).max() < 1e-3 * abs(w[0, 2])
    # R_{t+1} = R_t exp([w] dt) with w in the body frame.
    R = rot6d_to_matrix(s[:, 6:12])
    rel = np.einsum("tji,tjk->tik", R[:-1], R[1:])  # R_t^T R_{t+1}
    angle = np.arctan2(rel[:, 1, 0], rel[:, 0, 0])
    np.testing.assert_allclose(angle, w[1:, 2] * physics_env.sim.dt, rtol=1e-3)
