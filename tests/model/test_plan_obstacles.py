"""Obstacles as the planner sees them: depth back-projection, point clouds, true distances."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from orbitdata.scenario.geometry import signed_distance as reference_distance
from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.sim.config import CameraConfig, SimConfig
from orbitdata.sim.env import CubeSatEnv
from orbitdata.state import make_state
from orbitmodel.plan.mppi import MPPI, MPPIConfig
from orbitmodel.plan.obstacles import Camera, PointCloud, PointMemory, TrueObstacles, depth_to_points, signed_distance
from orbitmodel.plan.tracker import MovingCloud

torch.set_num_threads(1)


def _quat(q) -> tuple:
    q = np.asarray(q, float)
    return tuple(q / np.linalg.norm(q))


def test_camera_pose_is_the_simulators():
    cam = Camera.from_sim(SimConfig())
    R = np.asarray(cam.rotation)
    # optical axis (camera -z) = body +x, image up (camera +y) = body +z, image right = body -y
    assert np.allclose(-R[:, 2], [1, 0, 0]) and np.allclose(R[:, 1], [0, 0, 1]) and np.allclose(R[:, 0], [0, -1, 0])
    assert np.allclose(cam.position, [SimConfig().cubesat.half_size + 0.001, 0, 0])


def test_synthetic_wall_lands_on_the_right_world_points():
    cam = Camera.from_sim(SimConfig())
    # Body yawed by +90 deg (camera looks along world +y), at (1, 2, 3): a wall 4 m in front.
    R = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    state = make_state(np.array([1.0, 2, 3]), np.zeros(3), R, np.zeros(3), 1.0)
    depth = np.full((16, 16), 4.0)
    depth[0, 0] = cam.far  # no return: dropped
    points, radii = depth_to_points(depth, state, cam)
    assert len(points) == 255
    # Cell (row i, column j) centre at unit depth: right x_n, up y_n. Body = (offset + d, -d x_n,
    # d y_n) (image right = body -y, up = body +z); the yaw maps body (x, y, z) to world (-y, x, z).
    t = math.tan(math.radians(50))
    centres = ((np.arange(16) + 0.5) / 16 * 2 - 1) * t
    i, j = np.divmod(np.arange(256), 16)
    expected = np.stack([1 + 4.0 * centres[j], np.full(256, 2 + cam.position[0] + 4.0), 3 - 4.0 * centres[i]], -1)
    assert np.allclose(points, expected[1:], atol=1e-6)
    assert np.allclose(radii, 0.5 * 4.0 * 2 * t / 16)  # half a cell wide: neighbours touch


@pytest.mark.parametrize("quat", [(1, 0, 0, 0), (0.95, 0.05, -0.1, 0.2)])
def test_rendered_sphere_back_projects_onto_its_surface(quat):
    sim = SimConfig(camera=CameraConfig(image_size=64))
    centre, radius = np.array([4.0, 1.5, -0.5]), 1.2
    env = CubeSatEnv(sim)
    obs, _ = env.reset(
        options={
            "scenario": Scenario(
                obstacles=(Obstacle("sphere", tuple(centre), (radius, 0, 0)),),
                goal=(10.0, 0, 0),
                initial_quat=_quat(quat),
            )
        }
    )
    env.close()
    points, _ = depth_to_points(obs["depth_low"], obs["state"], Camera.from_sim(sim), max_range=50.0)
    # Cells whose 4x4 pixels all hit the sphere are means of its z-depth over the cell: they lie
    # on the surface up to the cell's curvature (measured: 3.5 cm at 2.5-4 m).
    whole = (obs["depth"].reshape(16, 4, 16, 4) > 0).all(axis=(1, 3))
    kept = obs["depth_low"] < 0.99 * sim.camera.far
    assert whole.sum() >= 6
    gap = np.linalg.norm(points - centre, axis=1) - radius
    assert np.abs(gap[whole[kept]]).max() < 0.06
    assert (gap > -0.06).all()  # mixed edge cells land behind the surface, never in front of it


def test_far_cells_are_dropped():
    cam = Camera.from_sim(SimConfig())
    depth = np.full((16, 16), 50.1)
    depth[3, 4] = 5.0
    depth[5, 5] = 15.0  # beyond max_range
    depth[6, 6] = np.nan
    points, _ = depth_to_points(
        depth, make_state(np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), 1.0), cam, max_range=10.0
    )
    assert len(points) == 1


def test_support_drops_lone_cells_and_keeps_surfaces():
    cam = Camera.from_sim(SimConfig())
    state = make_state(np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), 1.0)
    depth = np.full((16, 16), 50.1)
    depth[5:8, 5:8] = 3.0  # a surface: nine cells at one depth
    depth[12, 2] = 4.0  # a lone cell in the sky
    depth[0, 0], depth[0, 1] = 2.0, 2.5  # two neighbours within 30 % of each other's depth
    depth[15, 14], depth[15, 15] = 2.0, 6.0  # two neighbours at very different depths
    every, _ = depth_to_points(depth, state, cam, max_range=10.0)
    kept, radii = depth_to_points(depth, state, cam, max_range=10.0, support=1)
    assert len(every) == 14 and len(kept) == 11 and len(radii) == 11
    on_surface = depth_to_points(np.where(depth == 3.0, 3.0, 50.1), state, cam, max_range=10.0)[0]
    assert all(np.isclose(kept, p).all(1).any() for p in on_surface)
    corners_and_centre, _ = depth_to_points(depth, state, cam, max_range=10.0, support=3)
    assert len(corners_and_centre) == 9  # each cell of the 3x3 block has >= 3 neighbours in it
    assert len(depth_to_points(depth, state, cam, max_range=10.0, support=8)[0]) == 1  # its centre


def test_support_neither_wraps_around_the_image_nor_counts_cells_out_of_range():
    cam = Camera.from_sim(SimConfig())
    state = make_state(np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), 1.0)
    depth = np.full((16, 16), 50.1)
    depth[0, 7], depth[15, 7] = 3.0, 3.0  # neighbours only if the grid wrapped around
    depth[8, 0], depth[8, 15] = 3.0, 3.0
    depth[4, 4], depth[4, 5] = 9.5, 10.5  # similar depths, but the second is beyond max_range
    assert len(depth_to_points(depth, state, cam, max_range=10.0)[0]) == 5
    assert len(depth_to_points(depth, state, cam, max_range=10.0, support=1)[0]) == 0


SHAPES = [
    Obstacle("sphere", (1.0, 2.0, 0.5), (0.7, 0, 0)),
    Obstacle("box", (0.0, -1.0, 1.0), (0.4, 0.6, 0.3), _quat((0.9, 0.2, -0.3, 0.1))),
    Obstacle("capsule", (2.0, 0.0, -1.0), (0.3, 0.5, 0), _quat((0.8, 0.1, 0.5, 0.0))),
    Obstacle("cylinder", (-1.0, 1.0, 0.0), (0.5, 0.4, 0), _quat((0.7, 0.0, 0.7, 0.1))),
    Obstacle("ellipsoid", (0.5, 0.5, -0.5), (0.8, 0.5, 0.6), _quat((0.6, 0.3, 0.2, 0.7))),
]


@pytest.mark.parametrize("ob", SHAPES, ids=lambda o: o.shape)
def test_true_signed_distance_matches_orbitdata(ob):
    x = np.random.default_rng(0).uniform(-3, 3, size=(300, 3))
    ours = signed_distance(ob, torch.tensor(x, dtype=torch.float32)).numpy()
    ref = np.array([reference_distance(ob, p) for p in x])
    assert np.allclose(ours, ref, atol=1e-5)


def test_true_obstacles_take_the_nearest():
    field = TrueObstacles(Scenario(obstacles=tuple(SHAPES), goal=(9.0, 0, 0)))
    x = torch.rand(4, 6, 3) * 6 - 3  # (K, H, 3)
    ref = np.array([min(reference_distance(ob, p) for ob in SHAPES) for p in x.reshape(-1, 3).double().numpy()])
    assert field.clearance(x).shape == (4, 6)
    assert np.allclose(field.clearance(x).reshape(-1).numpy(), ref, atol=1e-5)
    assert torch.isinf(TrueObstacles(Scenario(obstacles=(), goal=(9.0, 0, 0))).clearance(x)).all()


def test_point_cloud_clearance_is_the_nearest_sphere_within_reach():
    rng = np.random.default_rng(0)
    points, radii = rng.uniform(-2, 2, (50, 3)), rng.uniform(0.05, 0.2, 50)
    cloud = PointCloud(points, radii, reach=1.0)
    x = torch.tensor(rng.uniform(-3, 3, (20, 10, 3)), dtype=torch.float32)
    got = cloud.clearance(x)
    brute = (np.linalg.norm(x.double().numpy()[..., None, :] - points, axis=-1) - radii).min(-1)
    near = brute < 1.0
    assert np.allclose(got.numpy()[near], brute[near], atol=1e-5)
    assert (got.numpy()[~near] >= 1.0).all()  # beyond reach: reported far (+inf)
    assert torch.isinf(PointCloud(np.zeros((0, 3)), np.zeros(0)).clearance(x)).all()


def test_positions_far_from_the_cloud_are_beyond_reach_and_near_ones_exact():
    """Most candidates pass far from most clouds; those are answered +inf without a tree query,
    the ones near it exactly as before."""
    rng = np.random.default_rng(3)
    points, radii = rng.uniform(-0.5, 0.5, (40, 3)) + [5.0, 0.0, 0.0], rng.uniform(0.05, 0.2, 40)
    cloud = PointCloud(points, radii, reach=1.0)
    x = torch.tensor(rng.uniform(-10, 10, (64, 50, 3)), dtype=torch.float32)
    x[:8] = torch.tensor(rng.uniform(-1.5, 1.5, (8, 50, 3)) + [5.0, 0.0, 0.0], dtype=torch.float32)  # some near it
    got = cloud.clearance(x).numpy()
    centre = np.linalg.norm(x.double().numpy()[..., None, :] - points, axis=-1)  # (64, 50, 40)
    brute = (centre - radii).min(-1)
    near = brute < 1.0
    assert near.sum() > 50 and (centre.min(-1) > 1.0 + radii.max()).sum() > 1000
    assert np.allclose(got[near], brute[near], atol=1e-5)
    assert np.isinf(got[centre.min(-1) > 1.0 + radii.max()]).all()
    # to the bit what the tree answers when asked for every position, those on the box's faces too
    lo, hi = cloud.box
    x[8, :3] = torch.tensor(np.stack([lo, hi, [lo[0], 0.0, hi[2]]]), dtype=torch.float32)
    bound = 1.0 + radii.max()
    dist, idx = cloud._tree.query(x.reshape(-1, 3).double().numpy(), k=4, distance_upper_bound=bound)
    every = (dist - np.append(radii, 0.0)[idx]).min(-1).astype(np.float32).reshape(64, 50)
    np.testing.assert_array_equal(cloud.clearance(x).numpy(), every)


def test_a_diverged_candidate_gets_no_clearance_and_no_weight():
    """A rollout that diverged (inf or NaN positions) must not stop the flight: its clearance is NaN,
    so its cost is not finite and MPPI weighs it zero; the finite candidates' clearances are unchanged."""
    rng = np.random.default_rng(1)
    points, radii = rng.uniform(-2, 2, (50, 3)), rng.uniform(0.05, 0.2, 50)
    cloud = PointCloud(points, radii, reach=1.0)
    x = torch.tensor(rng.uniform(-3, 3, (4, 10, 3)), dtype=torch.float32)
    clean = cloud.clearance(x)
    x[1, 6:] = float("inf")
    x[2, 3, 0] = float("nan")
    got = cloud.clearance(x)
    assert torch.isnan(got[1, 6:]).all() and torch.isnan(got[2, 3]) and torch.isfinite(got[1, :6]).any()
    keep = ~torch.isnan(got)
    assert torch.equal(got[keep], clean[keep])
    moving = MovingCloud([(points, radii, np.array([0.5, 0.0, 0.0]))], time=0.0, reach=1.0)
    assert torch.isnan(moving.clearance(x, torch.arange(10) * 0.04)[1, 6:]).all()
    mppi = MPPI(MPPIConfig(samples=4, horizon=10))
    candidates = torch.rand(4, 10, 8)
    costs = torch.where(torch.isnan(got).any(1), torch.nan, got.nan_to_num(posinf=5.0).sum(1))
    result = mppi.update(candidates, costs)
    assert result.weights[1] == 0 and result.weights[2] == 0 and result.weights.sum().item() == pytest.approx(1.0)


def test_memory_keeps_the_last_frames():
    memory = PointMemory(frames=2)
    for k in range(3):
        memory.add(np.full((k + 1, 3), float(k)), np.ones(k + 1))
    cloud = memory.cloud()
    assert len(cloud) == 2 + 3 and cloud.points.min() == 1.0
