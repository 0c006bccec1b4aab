"""The thruster wrench matrix matches the geometry, and every wrench direction is reachable."""

import numpy as np
from scenes import free_space, pure_force_thrust
from scipy.optimize import linprog

from orbitdata.sim import CubeSatConfig, thruster_layout, wrench_matrix
from orbitdata.sim.thrusters import CORNERS


def test_layout_is_corners_with_canted_reference_directions():
    cfg = CubeSatConfig()
    pos, dirs = thruster_layout(cfg)
    np.testing.assert_allclose(pos, CORNERS * 0.05)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    for (sx, sy, sz), d in zip(CORNERS, dirs):
        exhaust = -d
        # The cant is a rotation about z: the z component of the reference direction stays.
        ref = np.array([0.5 * sx, 0.5 * sy, sz]) / np.linalg.norm([0.5, 0.5, 1.0])
        assert np.isclose(exhaust[2], ref[2])
        angle = np.degrees(np.arctan2(np.cross(ref[:2], exhaust[:2]), ref[:2] @ exhaust[:2]))
        assert np.isclose(angle, cfg.cant_deg * sx * sy * sz)


def test_wrench_matrix_is_force_and_moment_of_each_thruster():
    cfg = CubeSatConfig()
    pos, dirs = thruster_layout(cfg)
    W = wrench_matrix(cfg)
    assert W.shape == (6, 8)
    for i in range(8):
        f = cfg.max_thrust * dirs[i]
        np.testing.assert_allclose(W[:3, i], f)
        np.testing.assert_allclose(W[3:, i], np.cross(pos[i], f))


def test_full_rank_and_positive_spanning():
    W = wrench_matrix(CubeSatConfig())
    assert np.linalg.matrix_rank(W) == 6
    # Positive spanning <=> some strictly positive thrust vector gives zero wrench.
    res = linprog(np.zeros(8), A_eq=W, b_eq=np.zeros(6), bounds=[(1.0, None)] * 8)
    assert res.success
    # The uncanted reference layout cannot yaw: rank 5.
    assert np.linalg.matrix_rank(wrench_matrix(CubeSatConfig(cant_deg=0.0))) == 5


def test_simulated_acceleration_matches_wrench(physics_env):
    cfg = physics_env.sim.cubesat
    W = wrench_matrix(cfg)
    obs0, _ = physics_env.reset(options={"scenario": free_space()})
    u = pure_force_thrust(physics_env, [4.0, 0.0, 0.0])
    m0 = physics_env.mass
    obs1, _, _, _, info = physics_env.step(u)
    force = W @ u
    dv = obs1["state"][3:6] - obs0["state"][3:6]
    np.testing.assert_allclose(obs1["state"][12:15], 0.0, atol=1e-6)  # no torque, no spin
    expected = force[:3] / m0 * physics_env.sim.dt
    np.testing.assert_allclose(dv, expected, rtol=5e-3, atol=1e-6)  # mass drops slightly in-step
