"""The scenario sampler: a pure function of (seed, settings), covering the promised ranges."""

import math

import numpy as np
import pytest

from orbitdata.scenario import ScenarioConfig, clearance, sample_scenario, signed_distance
from orbitdata.scenario.spec import Obstacle, Scenario


def test_pure_function_of_seed_and_settings():
    assert sample_scenario(7) == sample_scenario(7)
    assert sample_scenario(7) != sample_scenario(8)
    assert sample_scenario(7, n_obstacles=3, speed=1.0) == sample_scenario(7, n_obstacles=3, speed=1.0)
    assert Scenario.from_dict(sample_scenario(7).to_dict()) == sample_scenario(7)


def test_ranges_are_covered_and_specs_are_valid():
    cfg = ScenarioConfig()
    scenarios = [sample_scenario(s) for s in range(300)]
    counts = {len(s.obstacles) for s in scenarios}
    assert counts == {1, 2, 3, 4, 5}
    speeds = [np.linalg.norm(s.initial_velocity) for s in scenarios]
    assert min(speeds) < 0.6 and max(speeds) > 2.4
    shapes = {o.shape for s in scenarios for o in s.obstacles}
    assert shapes == set(cfg.shapes)
    for s in scenarios:
        assert cfg.goal_distance[0] <= np.linalg.norm(s.goal) <= cfg.goal_distance[1]
        assert clearance(s.obstacles, (0, 0, 0)) >= cfg.start_clearance
        assert clearance(s.obstacles, s.goal) >= cfg.goal_radius + cfg.goal_clearance
    lights = np.array([[s.lighting.sun_intensity, s.lighting.ambient] for s in scenarios])
    assert lights.std(axis=0).min() > 0.05


def test_straight_line_is_often_blocked():
    """Some obstacles sit on the start-goal line, so flying straight is dangerous."""
    blocked = 0
    for seed in range(100):
        s = sample_scenario(seed, n_obstacles=5)
        line = [np.asarray(s.goal) * f for f in np.linspace(0, 1, 400)]
        blocked += min(clearance(s.obstacles, p) for p in line) < 0.1
    assert blocked > 80


@pytest.mark.parametrize(
    "ob, point, expected",
    [
        (Obstacle("sphere", (0, 0, 0), (1, 0, 0)), (3, 0, 0), 2.0),
        (Obstacle("box", (0, 0, 0), (1, 2, 3)), (0, 5, 0), 3.0),
        (Obstacle("box", (0, 0, 0), (1, 1, 1)), (2, 2, 1), math.sqrt(2)),
        (Obstacle("capsule", (0, 0, 0), (0.5, 1, 0)), (0, 0, 3), 1.5),
        (Obstacle("cylinder", (0, 0, 0), (0.5, 1, 0)), (2, 0, 0), 1.5),
        (Obstacle("sphere", (0, 0, 0), (1, 0, 0)), (0.5, 0, 0), -0.5),
    ],
)
def test_signed_distance_exact_shapes(ob, point, expected):
    assert signed_distance(ob, point) == pytest.approx(expected)


def test_ellipsoid_distance_is_a_lower_bound():
    ob = Obstacle("ellipsoid", (1, 2, 3), (0.5, 1.0, 2.0), quat=(0.9, 0.1, 0.3, 0.2))
    rng = np.random.default_rng(0)
    # Dense surface samples: true distance = min over them.
    u, v = rng.uniform(0, 2 * np.pi, 20000), rng.uniform(-np.pi / 2, np.pi / 2, 20000)
    local = np.stack([0.5 * np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), 2 * np.sin(v)], 1)
    surface = local @ ob.rotation.T + np.array(ob.center)
    for p in rng.uniform(-3, 6, size=(50, 3)):
        d = signed_distance(ob, p)
        if d > 0:
            assert d <= np.linalg.norm(surface - p, axis=1).min() + 1e-9


def test_bad_settings_are_rejected():
    with pytest.raises(ValueError, match="n_obstacles"):
        ScenarioConfig(n_obstacles=(3, 1))
    with pytest.raises(ValueError, match="shapes"):
        ScenarioConfig(shapes=("cube",))
    with pytest.raises(ValueError, match="n_obstacles"):
        ScenarioConfig(n_obstacles=(1, 10**20))
    # 2.5 used to reach range() as a bare TypeError; 10**20 ran for ever
    for bad in (-1, 2.5, True, 10**20):
        with pytest.raises(ValueError, match="n_obstacles must be a whole number from 0 to 1000"):
            sample_scenario(0, n_obstacles=bad)
