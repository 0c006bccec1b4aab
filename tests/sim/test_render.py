"""Rendering: shapes, dtypes, depth range and pooling."""

import numpy as np
import pytest
from scenes import wall_ahead

from orbitdata.sim.render import pool_depth


def test_image_shapes_and_dtypes(render_env):
    obs, _ = render_env.reset(seed=3)
    assert obs["image"].shape == (64, 64, 3) and obs["image"].dtype == np.uint8
    assert obs["depth"].shape == (64, 64) and obs["depth"].dtype == np.float32
    assert obs["depth_low"].shape == (16, 16) and obs["depth_low"].dtype == np.float32


def test_depth_is_metric_and_within_camera_range(render_env):
    obs, _ = render_env.reset(options={"scenario": wall_ahead(distance=1.0)})
    depth = obs["depth"]
    cam = render_env.sim.camera
    hits = depth[depth > 0]
    assert hits.size > 0.9 * depth.size  # the wall fills the view
    assert hits.min() >= cam.near and hits.max() <= cam.far
    # The camera sits on the front face; the wall face is 1 m ahead: z-depth 1 m at the centre.
    assert depth[32, 32] == pytest.approx(1.0 - 0.001, abs=0.01)
    # z-depth is constant across a plane facing the camera (not range).
    assert np.ptp(depth[16:48, 16:48]) < 0.02


def test_empty_space_has_no_return_and_pools_to_far(render_env):
    obs, _ = render_env.reset(options={"scenario": wall_ahead(distance=1.0)})
    render_env.reset(seed=0, options={"n_obstacles": 0})
    obs, *_ = render_env.step(np.zeros(8))
    assert np.all(obs["depth"] == 0)  # nothing within 50.1 m
    np.testing.assert_allclose(obs["depth_low"], render_env.sim.camera.far)
    assert obs["image"].max() == 0  # black space


def test_pool_depth_is_area_mean_with_no_return_as_far():
    depth = np.zeros((32, 32), np.float32)
    depth[:2, :2] = [[1, 2], [3, 0]]  # one 2x2 cell: 1, 2, 3 and a no-return pixel
    pooled = pool_depth(depth, far=10.0)
    assert pooled.shape == (16, 16)
    assert pooled[0, 0] == pytest.approx((1 + 2 + 3 + 10) / 4)
    assert pooled[5, 5] == pytest.approx(10.0)


def test_every_obstacle_of_a_crowded_scene_is_drawn(render_env):
    """The scene has room for all of a model's geoms: 80 obstacles are all drawn, none dropped."""
    render_env.reset(seed=0, options={"n_obstacles": 80})
    render_env.step(np.zeros(8))
    scene = render_env._renderer._scene
    assert scene.ngeom >= 80 + 1 and scene.ngeom < scene.maxgeom  # every obstacle and the goal, with room to spare
