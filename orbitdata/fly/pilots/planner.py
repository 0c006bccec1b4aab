"""OMPL RRT* path planning for the expert pilot, in 3-D position space.

The CubeSat is planned as a point; obstacles are inflated by the caller's ``inflation``
(body radius + safety margin): a point is free iff ``clearance(obstacles, p) > inflation``.

Determinism (the hard requirement: a plan is a pure function of its inputs and ``rng``)
---------------------------------------------------------------------------------------
OMPL's own RNGs are seeded from one process-wide sequence, so a plan would depend on every
plan made before it in the process. The OMPL 2.x nanobind bindings cannot install a custom
``StateSampler`` on a state space (no ``setStateSamplerAllocator``; overriding
``allocDefaultStateSampler`` in Python is never called from C++). They do, however, have a
trampoline for ``GoalSampleableRegion``, and RRT* draws its sample from the goal whenever
``rng_.uniform01() < goalBias``. With ``setGoalBias(1.0)`` that is every iteration, so our
goal's ``sampleGoal`` is RRT*'s only sampler: it returns the goal point with probability
``config.goal_bias`` and otherwise a uniform point of the box, all drawn from the numpy
``rng``. OMPL's uniform01 draw still happens but cannot change anything, and informed,
rejection and ordered sampling (which bypass this route) are switched off. Collision checks
go through our own ``MotionValidator`` (pure Python, deterministic), the run stops after a
fixed number of iterations (a counting ``PlannerTerminationCondition``), and the final
shortcutting is ours, because OMPL's PathSimplifier uses OMPL's RNG. Nearest-neighbour
structures use OMPL RNGs internally but return exact answers, so they cannot change a plan.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from orbitdata.fly.pilots.config import PlannerConfig
from orbitdata.scenario.geometry import signed_distance
from orbitdata.scenario.spec import Obstacle

ou.setLogLevel(ou.LogLevel.LOG_NONE)

# m. Keeps "clearance > inflation" strict despite rounding in the interpolation and bounds.
_EPS = 1e-9
_GOAL_TOL = 1e-9  # m, only the exact goal point satisfies the goal: the path ends on it
_CHUNK = 512  # samples drawn from the numpy rng at a time (one numpy call, not one per sample)


@dataclass(frozen=True)
class PlanResult:
    path: np.ndarray  # (N, 3) float64 waypoints (m), start first, goal last when solved
    solved: bool  # False if RRT* found no exact solution within its budget
    iterations: int  # RRT* iterations run (0 for the straight-line fast path)
    path_length: float  # m
    planning_time: float  # s of wall time, informative only


class FreeSpace:
    """Clearance queries against inflated obstacles, in pure Python (the planner's hot loop)."""

    def __init__(self, obstacles: Sequence[Obstacle], inflation: float, resolution: float) -> None:
        self.inflation = float(inflation)
        self.resolution = float(resolution)
        # A cheap lower bound of each obstacle's signed distance, (|p - c| - r) * k, lets most
        # exact evaluations be skipped without changing the minimum. For the ellipsoid the
        # geometry module returns (k_ell - 1) * min(size) >= (|p - c| / max - 1) * min(size).
        self._obs = []
        for o in obstacles:
            r, k = o.bounding_radius, 1.0
            if o.shape == "ellipsoid":
                r, k = max(o.size), min(o.size) / max(o.size)
            self._obs.append((float(o.center[0]), float(o.center[1]), float(o.center[2]), r, k, o))
        self._cache: dict[tuple[float, float, float], float] = {}

    def margin(self, x: float, y: float, z: float) -> float:
        """clearance - inflation (m), minus a rounding guard; > 0 means the point is free.

        Equal to ``geometry.clearance`` up to that guard, since skipped obstacles cannot hold
        the minimum. Clearance is 1-Lipschitz, so every point closer than ``margin`` is free too.
        """
        best = math.inf
        for cx, cy, cz, r, k, o in self._obs:
            dx, dy, dz = x - cx, y - cy, z - cz
            if (math.sqrt(dx * dx + dy * dy + dz * dz) - r) * k - _EPS < best:
                d = signed_distance(o, (x, y, z))
                if d < best:
                    best = d
        return best - self.inflation - _EPS

    def cached_margin(self, p: tuple[float, float, float]) -> float:
        # Tree vertices start many motion checks (rewiring), so their margins are memoised.
        m = self._cache.get(p)
        if m is None:
            m = self._cache[p] = self.margin(*p)
        return m

    def segment_free(self, a: Sequence[float], b: Sequence[float]) -> bool:
        """True if every point of segment a-b is free (conservative near the surface).

        Sphere tracing: from a point with margin m the next check is m further on (at least
        ``resolution``), and two consecutive checks must have overlapping free balls. So the
        whole segment is proven free, and a segment costs a few checks unless it grazes.
        """
        ax, ay, az = a[0], a[1], a[2]
        dx, dy, dz = b[0] - ax, b[1] - ay, b[2] - az
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        m = self.cached_margin((ax, ay, az))
        if m <= 0.0:
            return False
        t = 0.0
        while t + m <= length:  # the free ball about p(t) does not reach b yet
            step = m if m >= self.resolution else self.resolution
            t_next = t + step
            if t_next >= length:
                t_next = length
                m_next = self.cached_margin((b[0], b[1], b[2]))
            else:
                f = t_next / length
                m_next = self.margin(ax + f * dx, ay + f * dy, az + f * dz)
            if m_next <= 0.0 or m + m_next <= t_next - t:
                return False
            t, m = t_next, m_next
        return True


class _MotionValidator(ob.MotionValidator):
    def __init__(self, si: ob.SpaceInformation, free: FreeSpace) -> None:
        super().__init__(si)
        self._free = free

    def checkMotion(self, s1, s2) -> bool:  # noqa: N802 (OMPL's name)
        return self._free.segment_free((s1[0], s1[1], s1[2]), (s2[0], s2[1], s2[2]))


class _SamplingGoal(ob.GoalSampleableRegion):
    """The goal point, which is also RRT*'s only source of samples (see the module docstring)."""

    def __init__(self, si, goal, low, high, goal_bias: float, rng: np.random.Generator) -> None:
        super().__init__(si)
        self.setThreshold(_GOAL_TOL)
        self._goal = goal
        self._low = low
        self._span = tuple(h - lo for h, lo in zip(high, low))
        self._bias = goal_bias
        self._rng = rng
        self._draws: list[list[float]] = []
        self._next = 0
        self.reached = False

    def sampleGoal(self, st) -> None:  # noqa: N802
        if self._next >= len(self._draws):
            self._draws = self._rng.random((_CHUNK, 4)).tolist()
            self._next = 0
        u, x, y, z = self._draws[self._next]
        self._next += 1
        if u < self._bias and not self.reached:
            # Once the goal is in the tree, another copy would only add zero-distance ties.
            x, y, z = self._goal
        else:
            x = self._low[0] + x * self._span[0]
            y = self._low[1] + y * self._span[1]
            z = self._low[2] + z * self._span[2]
        st[0], st[1], st[2] = x, y, z

    def maxSampleCount(self) -> int:  # noqa: N802 (RRT* stops goal-sampling at this many)
        return 1 << 30

    def couldSample(self) -> bool:  # noqa: N802
        return True

    def distanceGoal(self, st) -> float:  # noqa: N802
        g = self._goal
        d = math.sqrt((st[0] - g[0]) ** 2 + (st[1] - g[1]) ** 2 + (st[2] - g[2]) ** 2)
        if d <= _GOAL_TOL:
            self.reached = True
        return d


def _point(p, name: str) -> tuple[float, float, float]:
    a = np.asarray(p, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {p!r}")
    return (float(a[0]), float(a[1]), float(a[2]))


def _length(pts: Sequence[Sequence[float]]) -> float:
    return float(sum(math.dist(pts[i], pts[i + 1]) for i in range(len(pts) - 1)))


def shortcut(pts: list[tuple[float, float, float]], free: FreeSpace) -> list[tuple[float, float, float]]:
    """Greedy line-of-sight shortening: from each waypoint jump to the farthest visible one."""
    out, i, n = [pts[0]], 0, len(pts)
    while i < n - 1:
        j = n - 1
        while j > i + 1 and not free.segment_free(pts[i], pts[j]):
            j -= 1
        out.append(pts[j])  # j == i + 1 keeps the planner's own (already checked) edge
        i = j
    return out


def _result(pts, solved: bool, iterations: int, t0: float) -> PlanResult:
    path = np.array(pts, dtype=np.float64).reshape(-1, 3)
    path.setflags(write=False)
    return PlanResult(path, solved, iterations, _length(pts), time.perf_counter() - t0)


def plan_path(
    start,
    goal,
    obstacles: Sequence[Obstacle],
    inflation: float,
    config: PlannerConfig,
    rng: np.random.Generator,
) -> PlanResult:
    """Plan a collision-free polyline from ``start`` to ``goal`` (metres, world frame).

    Never raises for a planning failure: an invalid start or goal, or no exact solution
    within ``config.iterations``, gives ``solved=False`` with RRT*'s best approximate path
    (ending at the tree vertex closest to the goal) or, failing that, the straight line.
    """
    t0 = time.perf_counter()
    s, g = _point(start, "start"), _point(goal, "goal")
    if not (math.isfinite(inflation) and inflation >= 0):
        raise ValueError(f"inflation must be a finite number >= 0, got {inflation}")
    free = FreeSpace(obstacles, inflation, config.resolution)
    if free.cached_margin(s) <= 0 or free.cached_margin(g) <= 0:
        return _result([s, g], False, 0, t0)
    if free.segment_free(s, g):
        return _result([s, g], True, 0, t0)

    low = tuple(min(a, b) - config.bounds_pad for a, b in zip(s, g))
    high = tuple(max(a, b) + config.bounds_pad for a, b in zip(s, g))
    space = ob.RealVectorStateSpace(3)
    bounds = ob.RealVectorBounds(3)
    for k in range(3):
        bounds.setLow(k, low[k])
        bounds.setHigh(k, high[k])
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(lambda st: free.margin(st[0], st[1], st[2]) > 0.0)
    validator = _MotionValidator(si, free)
    si.setMotionValidator(validator)
    si.setup()

    start_state = space.allocState()
    start_state[0], start_state[1], start_state[2] = s
    pdef = ob.ProblemDefinition(si)
    pdef.addStartState(start_state)
    goal_region = _SamplingGoal(si, g, low, high, config.goal_bias, rng)
    pdef.setGoal(goal_region)

    planner = og.RRTstar(si)
    planner.setProblemDefinition(pdef)
    planner.setRange(config.max_range)
    planner.setGoalBias(1.0)  # every sample comes from _SamplingGoal, i.e. from rng
    planner.setInformedSampling(False)
    planner.setSampleRejection(False)
    planner.setOrderedSampling(False)
    planner.setNewStateRejection(False)
    planner.setTreePruning(False)
    planner.setup()

    calls = [0]

    def out_of_budget() -> bool:  # evaluated once before each iteration
        calls[0] += 1
        return calls[0] > config.iterations

    planner.solve(ob.PlannerTerminationCondition(out_of_budget))
    iterations = int(planner.numIterations())
    solved = bool(pdef.hasExactSolution())
    if not pdef.hasSolution():
        return _result([s, g], False, iterations, t0)
    pts = [(st[0], st[1], st[2]) for st in pdef.getSolutionPath().getStates()]
    pts[0] = s
    if solved:
        pts[-1] = g  # already equal to within _GOAL_TOL (1 nm)
    return _result(shortcut(pts, free), solved, iterations, t0)
