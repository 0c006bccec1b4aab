"""orbitdata.state: rot6d <-> matrices and SO(3) exp/log, with batch dimensions, and the slices."""

import numpy as np
import pytest

from orbitdata import schema as S
from orbitdata.state import (
    ANGULAR_VELOCITY,
    FUEL,
    POSITION,
    ROT6D,
    STATE_NAMES,
    STATE_SLICES,
    VELOCITY,
    matrix_to_rot6d,
    quat_to_matrix,
    rot6d_to_matrix,
    so3_exp,
    so3_log,
)


def random_rotvecs(n: int, seed: int = 0, max_angle: float = np.pi) -> np.ndarray:
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return axis * rng.uniform(0, max_angle, (n, 1))


def test_the_slices_tile_the_state_in_the_upstream_order():
    covered = np.concatenate([np.arange(16)[s] for s in (POSITION, VELOCITY, ROT6D, ANGULAR_VELOCITY, FUEL)])
    np.testing.assert_array_equal(covered, np.arange(S.STATE_DIM))
    assert list(STATE_SLICES.values()) == [POSITION, VELOCITY, ROT6D, ANGULAR_VELOCITY, FUEL]
    assert [STATE_NAMES[i] for i in range(16)[ROT6D]] == ["r_00", "r_01", "r_10", "r_11", "r_20", "r_21"]


def test_rot6d_is_row_major_first_two_columns():
    R = np.arange(9.0).reshape(3, 3)
    np.testing.assert_array_equal(matrix_to_rot6d(R), [0, 1, 3, 4, 6, 7])
    q = np.array([0.9, 0.1, -0.3, 0.2])
    R = quat_to_matrix(q / np.linalg.norm(q))
    np.testing.assert_allclose(rot6d_to_matrix(matrix_to_rot6d(R)), R, atol=1e-12)


def test_rot6d_round_trips_with_batch_dimensions():
    R = so3_exp(random_rotvecs(24).reshape(2, 3, 4, 3))  # (2, 3, 4, 3, 3)
    r6 = matrix_to_rot6d(R)
    assert r6.shape == (2, 3, 4, 6)
    back = rot6d_to_matrix(r6)
    assert back.shape == R.shape
    np.testing.assert_allclose(back, R, atol=1e-12)
    # the one-state fast path agrees with the batched path
    np.testing.assert_allclose(rot6d_to_matrix(r6[1, 2, 3]), back[1, 2, 3], atol=1e-15)


def test_rot6d_to_matrix_orthonormalises_any_six_numbers():
    r6 = np.random.default_rng(1).normal(size=(100, 6))
    R = rot6d_to_matrix(r6)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # Gram-Schmidt keeps the direction of the first column
    first = r6[:, [0, 2, 4]]
    np.testing.assert_allclose(R[..., 0], first / np.linalg.norm(first, axis=1, keepdims=True), atol=1e-12)


@pytest.mark.parametrize("max_angle", [np.pi - 1e-6, 1e-8, np.pi])
def test_so3_log_inverts_so3_exp(max_angle):
    w = random_rotvecs(200, seed=2, max_angle=max_angle)
    if max_angle == np.pi:  # exactly pi: the sign of the axis is a convention, the rotation is not
        w = w / np.linalg.norm(w, axis=1, keepdims=True) * np.pi
    R = so3_exp(w)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    back = so3_log(R)
    assert back.shape == w.shape
    np.testing.assert_allclose(so3_exp(back), R, atol=1e-7)
    if max_angle < np.pi - 1e-3 or max_angle < 1e-3:
        np.testing.assert_allclose(back, w, atol=1e-9)
    # one matrix at a time (the controller's path) gives the same answers
    for i in range(0, 200, 37):
        np.testing.assert_allclose(so3_log(R[i]), back[i], atol=1e-9)


def test_so3_exp_of_zero_is_the_identity_and_matches_a_known_rotation():
    np.testing.assert_array_equal(so3_exp(np.zeros(3)), np.eye(3))
    Rz = so3_exp(np.array([0.0, 0.0, np.pi / 2]))
    np.testing.assert_allclose(Rz @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)


def test_attitude_integration_as_a_probe_does_it():
    # R <- R exp(w dt) with body-frame w: 25 steps of 0.04 s at 0.5 rad/s about body z is 0.5 rad.
    R = np.eye(3)
    for _ in range(25):
        R = R @ so3_exp(np.array([0.0, 0.0, 0.5]) * S.DT)
    np.testing.assert_allclose(so3_log(R), [0.0, 0.0, 0.5], atol=1e-12)
