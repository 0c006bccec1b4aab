"""RRT* expert planner: safety of the paths, exact determinism, graceful failure."""

from __future__ import annotations

import hashlib
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from orbitdata.fly.pilots.planner import PlannerConfig, plan_path
from orbitdata.scenario import Obstacle, clearance, sample_scenario
from orbitdata.seeding import rng
from orbitdata.sim.config import CubeSatConfig

CFG = PlannerConfig()
INFLATION = CubeSatConfig().bounding_radius + CFG.margin  # hull bounding radius + safety margin, m
REPO = Path(__file__).resolve().parents[2]


def _plan(seed: int, config: PlannerConfig = CFG):
    scn = sample_scenario(seed, n_obstacles=5, speed=2.0)
    return scn, plan_path((0.0, 0.0, 0.0), scn.goal, scn.obstacles, INFLATION, config, rng(seed, "planner"))


def _digest(path: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(path, dtype=np.float64).tobytes()).hexdigest()


def _min_margin(obstacles, path: np.ndarray, step: float = 0.01) -> float:
    """Smallest clearance - inflation along the polyline, sampled every ``step`` metres."""
    worst = math.inf
    for a, b in zip(path[:-1], path[1:]):
        n = max(2, int(math.ceil(np.linalg.norm(b - a) / step)) + 1)
        for f in np.linspace(0.0, 1.0, n):
            worst = min(worst, clearance(obstacles, a + (b - a) * f) - INFLATION)
    return worst


@pytest.mark.parametrize("seed", range(10))
def test_paths_avoid_inflated_obstacles(seed):
    scn, res = _plan(seed)
    assert res.solved
    assert res.path.dtype == np.float64 and res.path.ndim == 2 and res.path.shape[1] == 3
    assert np.array_equal(res.path[0], [0.0, 0.0, 0.0])
    assert np.array_equal(res.path[-1], scn.goal)
    assert _min_margin(scn.obstacles, res.path) > 0.0
    assert res.path_length == pytest.approx(np.sum(np.linalg.norm(np.diff(res.path, axis=0), axis=1)))
    assert res.path_length >= math.dist((0, 0, 0), scn.goal) - 1e-9


def test_straight_line_fast_path():
    far = Obstacle("sphere", (0.0, 5.0, 0.0), (1.0, 0.0, 0.0))
    res = plan_path((0, 0, 0), (8, 0, 0), [far], INFLATION, CFG, np.random.default_rng(0))
    assert res.solved and res.iterations == 0
    assert res.path.tolist() == [[0, 0, 0], [8, 0, 0]]


def test_blocked_on_the_line_needs_rrt_and_detours():
    rock = Obstacle("box", (4.0, 0.0, 0.0), (0.6, 0.6, 0.6))
    res = plan_path((0, 0, 0), (8, 0, 0), [rock], INFLATION, CFG, np.random.default_rng(1))
    assert res.solved and res.iterations == CFG.iterations
    assert len(res.path) >= 3
    assert _min_margin([rock], res.path) > 0.0


def test_same_seed_same_path():
    a = _plan(3)[1]
    b = _plan(3)[1]
    assert a.path.tobytes() == b.path.tobytes()


def test_history_does_not_change_a_plan():
    """Workers plan many episodes in arbitrary order: A, B, A must give identical A."""
    first = _plan(4)[1]
    other = _plan(7)[1]
    again = _plan(4)[1]
    assert first.path.tobytes() == again.path.tobytes()
    assert first.path.tobytes() != other.path.tobytes()


def test_different_rng_gives_a_different_tree():
    scn = sample_scenario(5, n_obstacles=5, speed=2.0)
    cfg = PlannerConfig(iterations=300)
    a = plan_path((0, 0, 0), scn.goal, scn.obstacles, INFLATION, cfg, np.random.default_rng(1))
    b = plan_path((0, 0, 0), scn.goal, scn.obstacles, INFLATION, cfg, np.random.default_rng(2))
    assert a.path.tobytes() != b.path.tobytes()


def test_subprocess_gives_the_same_path():
    _plan(9)  # this process has planned before; the fresh one has not
    here = [_digest(_plan(seed)[1].path) for seed in (2, 6)]
    code = (
        "import hashlib, numpy as np\n"
        "from orbitdata.fly.pilots.planner import PlannerConfig, plan_path\n"
        "from orbitdata.scenario import sample_scenario\n"
        "from orbitdata.seeding import rng\n"
        "from orbitdata.sim.config import CubeSatConfig\n"
        "cfg = PlannerConfig()\n"
        "for seed in (6, 2):\n"  # the other order, too
        "    scn = sample_scenario(seed, n_obstacles=5, speed=2.0)\n"
        "    r = plan_path((0.0, 0.0, 0.0), scn.goal, scn.obstacles, CubeSatConfig().bounding_radius + cfg.margin,\n"
        "                  cfg, rng(seed, 'planner'))\n"
        "    print(seed, hashlib.sha256(np.ascontiguousarray(r.path).tobytes()).hexdigest())\n"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=120, check=True
    ).stdout
    there = dict(line.split() for line in out.splitlines() if line[:1].isdigit())
    assert [there["2"], there["6"]] == here


def _cage(center, gap=2.0, wall=0.2, half=2.4):
    """Six box walls enclosing ``center`` on every side."""
    walls = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            c = list(center)
            c[axis] += sign * gap
            size = [half, half, half]
            size[axis] = wall
            walls.append(Obstacle("box", tuple(c), tuple(size)))
    return walls


def test_enclosed_goal_is_reported_not_raised():
    goal = (10.0, 0.0, 0.0)
    cage = _cage(goal)
    res = plan_path((0, 0, 0), goal, cage, INFLATION, PlannerConfig(iterations=300), np.random.default_rng(0))
    assert not res.solved
    assert res.iterations == 300
    assert np.array_equal(res.path[0], [0, 0, 0])
    assert res.path.shape[1] == 3 and math.isfinite(res.path_length)
    assert _min_margin(cage, res.path) > 0.0  # the approximate path is still safe


def test_goal_inside_an_obstacle_is_reported_not_raised():
    rock = Obstacle("sphere", (8.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    res = plan_path((0, 0, 0), (8.0, 0.2, 0.0), [rock], INFLATION, CFG, np.random.default_rng(0))
    assert not res.solved
    assert res.path.tolist() == [[0, 0, 0], [8.0, 0.2, 0.0]]


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="start must be 3 finite numbers"):
        plan_path((0, 0), (1, 0, 0), [], INFLATION, CFG, np.random.default_rng(0))
    with pytest.raises(ValueError, match="goal must be 3 finite numbers"):
        plan_path((0, 0, 0), (1, 0, math.nan), [], INFLATION, CFG, np.random.default_rng(0))
    with pytest.raises(ValueError, match="planner.max_range must be > 0"):
        PlannerConfig(max_range=0.0)
