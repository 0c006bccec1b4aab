"""Waypoints -> rounded, time-parametrised reference: safety, dynamics limits, tracking index."""

from __future__ import annotations

import math

import numpy as np
import pytest

from orbitdata.fly.pilots.planner import PlannerConfig, plan_path
from orbitdata.fly.pilots.trajectory import TrajectoryConfig, time_parametrise
from orbitdata.scenario import Obstacle, clearance, sample_scenario
from orbitdata.seeding import rng
from orbitdata.sim.config import CubeSatConfig

CFG = TrajectoryConfig()
INFLATION = CubeSatConfig().bounding_radius + PlannerConfig().margin  # m
TOL = 1e-9


@pytest.fixture(scope="module")
def planned():
    out = []
    for seed in range(4):
        scn = sample_scenario(seed, n_obstacles=5, speed=2.0)
        res = plan_path((0, 0, 0), scn.goal, scn.obstacles, INFLATION, PlannerConfig(), rng(seed, "planner"))
        out.append((scn, res.path))
    return out


def _check_limits(tr, cfg: TrajectoryConfig, v0: float) -> None:
    ds = np.diff(tr.s)
    assert np.all(ds > 0) and np.all(ds <= cfg.spacing + TOL)
    assert tr.speed[0] == pytest.approx(v0) and tr.speed[-1] == pytest.approx(cfg.goal_speed)
    assert np.all(np.abs(np.diff(tr.speed**2)) <= 2 * cfg.max_accel * ds + 1e-9)
    assert np.all(tr.speed**2 * tr.curvature <= cfg.max_lateral_accel + 1e-9)
    assert np.all(tr.speed <= max(cfg.cruise_speed, v0) + TOL)
    assert np.allclose(np.linalg.norm(tr.tangents, axis=1), 1.0)


def test_planned_paths_stay_valid_and_within_limits(planned):
    for scn, path in planned:
        tr = time_parametrise(path, 2.0, CFG, scn.obstacles, INFLATION)
        margins = [clearance(scn.obstacles, p) - INFLATION for p in tr.points]
        assert min(margins) > 0.0
        assert np.array_equal(tr.points[0], path[0]) and np.array_equal(tr.points[-1], path[-1])
        _check_limits(tr, CFG, 2.0)
        # rounding only cuts corners, so the reference is never longer than the waypoints
        assert tr.s[-1] <= np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)) + TOL
        assert tr.duration > tr.s[-1] / CFG.cruise_speed


def test_samples_are_continuous_and_tangent(planned):
    scn, path = planned[1]
    tr = time_parametrise(path, 1.0, CFG, scn.obstacles, INFLATION)
    steps = np.linalg.norm(np.diff(tr.points, axis=0), axis=1)
    assert np.all(steps <= np.diff(tr.s) + 1e-9)  # chords never exceed arc length
    chord = np.diff(tr.points, axis=0) / steps[:, None]
    assert np.all(np.sum(chord * tr.tangents[:-1], axis=1) > 0.99)  # no kinks at 5 cm spacing


def test_rounding_shrinks_near_an_obstacle():
    path = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [5.0, 5.0, 0.0]])
    rock = Obstacle("sphere", (4.5, 0.5, 0.0), (0.32, 0.0, 0.0))  # inside the corner
    inflation = 0.15  # the polyline clears it by 0.03 m, the full 0.6 m arc would not
    blind = time_parametrise(path, 0.0, CFG)
    assert min(clearance([rock], p) for p in blind.points) <= inflation
    careful = time_parametrise(path, 0.0, CFG, [rock], inflation)
    assert min(clearance([rock], p) for p in careful.points) > inflation
    assert careful.curvature.max() > blind.curvature.max()  # a tighter, still rounded corner
    _check_limits(careful, CFG, 0.0)


def test_corner_speed_and_accel_limits_from_high_speed():
    path = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 6.0, 2.0], [14.0, 6.0, 2.0]])
    tr = time_parametrise(path, 2.0, CFG)
    _check_limits(tr, CFG, 2.0)
    corner = tr.curvature > 0
    assert corner.any()
    assert np.all(tr.speed[corner] <= math.sqrt(CFG.max_lateral_accel * CFG.corner_radius) + 1e-9)
    assert tr.curvature.max() == pytest.approx(1.0 / CFG.corner_radius)
    assert tr.speed.max() == pytest.approx(CFG.cruise_speed)


def test_v0_above_cruise_brakes_at_max_accel():
    tr = time_parametrise(np.array([[0, 0, 0], [20.0, 0, 0]]), 3.0, CFG)
    _check_limits(tr, CFG, 3.0)
    assert tr.speed[1] < 3.0


def test_reference_vectors(planned):
    scn, path = planned[2]
    tr = time_parametrise(path, 0.5, CFG, scn.obstacles, INFLATION)
    for i in range(0, len(tr), 7):
        pos, vel, acc = tr.reference(i)
        assert np.array_equal(pos, tr.points[i])
        assert np.allclose(vel, tr.speed[i] * tr.tangents[i])
        along = float(acc @ tr.tangents[i])
        lateral = np.linalg.norm(acc - along * tr.tangents[i])
        assert abs(along) <= CFG.max_accel + 1e-6
        assert lateral <= CFG.max_lateral_accel + 1e-6
    assert np.array_equal(tr.reference(10**6)[0], tr.points[-1])  # clamped, not an IndexError


def test_closest_progresses_monotonically(planned):
    scn, path = planned[3]
    tr = time_parametrise(path, 2.0, CFG, scn.obstacles, INFLATION)
    noise = np.random.default_rng(0).normal(scale=0.1, size=tr.points.shape)
    hint, seen = 0, []
    for k in range(0, len(tr), 3):  # a craft that flies near the reference, ~3 samples per step
        hint = tr.closest(tr.points[k] + noise[k], hint)
        seen.append(hint)
    assert all(b >= a for a, b in zip(seen, seen[1:]))
    assert seen[-1] >= len(tr) - 8
    # far ahead of the window, it does not jump: progress stays within the window of the hint
    assert tr.s[tr.closest(tr.points[-1], 0)] <= tr.window + 1e-9


def test_deterministic_and_degenerate_inputs():
    path = np.array([[0, 0, 0], [3.0, 1, 0], [3.0, 1, 0], [6.0, -1, 1]])
    a = time_parametrise(path, 1.0, CFG)
    b = time_parametrise(path, 1.0, CFG)
    assert a.points.tobytes() == b.points.tobytes() and a.speed.tobytes() == b.speed.tobytes()
    single = time_parametrise(np.array([[1.0, 2.0, 3.0]]), 1.0, CFG)
    assert len(single) == 1 and single.duration == 0.0
    with pytest.raises(ValueError):
        time_parametrise(np.zeros((0, 3)), 1.0, CFG)
    with pytest.raises(ValueError):
        time_parametrise(path, -1.0, CFG)
