"""Draw a random episode world as a pure function of (seed, settings)."""

from __future__ import annotations

import math
import numbers

import numpy as np

from orbitdata.scenario.config import ScenarioConfig
from orbitdata.scenario.geometry import clearance
from orbitdata.scenario.spec import Lighting, Obstacle, Scenario
from orbitdata.seeding import rng as make_rng


class ImpossibleScenario(ValueError):
    """A scenario spec that cannot be flown (goal inside an obstacle, blocked start)."""


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _random_quat(rng: np.random.Generator) -> tuple[float, ...]:
    q = rng.normal(size=4)
    q = q / np.linalg.norm(q)
    return tuple(float(x) for x in (q if q[0] >= 0 else -q))


def _cone(rng: np.random.Generator, axis: np.ndarray, max_deg: float) -> np.ndarray:
    """A unit vector within ``max_deg`` of ``axis``, uniform over the spherical cap."""
    axis = _unit(axis)
    cos_max = math.cos(math.radians(max_deg))
    cos_t = 1.0 - rng.uniform() * (1.0 - cos_max)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = _unit(np.cross(axis, helper))
    e2 = np.cross(axis, e1)
    phi = rng.uniform(0.0, 2.0 * math.pi)
    return cos_t * axis + sin_t * (math.cos(phi) * e1 + math.sin(phi) * e2)


def _euler_quat(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def _obstacle_size(rng: np.random.Generator, shape: str, scale: float) -> tuple[float, float, float]:
    if shape == "sphere":
        return (scale, 0.0, 0.0)
    if shape in ("ellipsoid", "box"):
        dims = scale * rng.uniform(0.6, 1.0, size=3)
        if shape == "box":
            dims = dims * 0.8  # a box's corners reach sqrt(3) times its half-extent
        return tuple(float(x) for x in dims)
    # capsule / cylinder: (radius, half-length)
    return (float(scale * rng.uniform(0.5, 0.8)), float(scale * rng.uniform(0.6, 1.0)), 0.0)


def _rock_rgba(rng: np.random.Generator) -> tuple[float, float, float, float]:
    grey = rng.uniform(0.35, 0.8)
    warm = rng.uniform(0.0, 0.2)
    return (float(min(1.0, grey * (1 + warm))), float(grey), float(grey * (1 - warm)), 1.0)


def check_scenario(scn: Scenario, body_radius: float, start_clearance: float = 0.0) -> None:
    """Raise ImpossibleScenario if the start overlaps an obstacle or the goal is blocked."""
    start = clearance(scn.obstacles, (0.0, 0.0, 0.0))
    if start < body_radius + start_clearance:
        raise ImpossibleScenario(
            f"the start overlaps an obstacle (clearance {start:.3f} m < {body_radius + start_clearance:.3f} m); "
            "move the obstacle away from the origin"
        )
    goal = clearance(scn.obstacles, scn.goal)
    if goal < scn.goal_radius:
        raise ImpossibleScenario(
            f"the goal region at {tuple(round(g, 3) for g in scn.goal)} is inside or touches an obstacle "
            f"(clearance {goal:.3f} m < goal radius {scn.goal_radius} m); move the goal or the obstacle"
        )


def sample_scenario(
    seed: int,
    config: ScenarioConfig = ScenarioConfig(),
    n_obstacles: int | None = None,
    speed: float | None = None,
) -> Scenario:
    """Sample the world of one episode. The same (seed, config, overrides) give the same world.

    ``n_obstacles`` and ``speed`` override the random draw (the evaluation grid fixes them).
    Obstacles that would overlap the start or block the goal are redrawn from the same
    generator, so the result stays deterministic.
    """
    rng = make_rng(seed, "scenario")
    c = config
    n = int(rng.integers(c.n_obstacles[0], c.n_obstacles[1] + 1))
    if n_obstacles is not None:
        if isinstance(n_obstacles, bool) or not isinstance(n_obstacles, numbers.Integral) or n_obstacles < 0:
            raise ValueError(f"n_obstacles must be a whole number >= 0, got {n_obstacles!r}")
        n = int(n_obstacles)
    v0 = float(rng.uniform(*c.speed))
    if speed is not None:
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed must be a finite non-negative number, got {speed}")
        v0 = float(speed)

    distance = rng.uniform(*c.goal_distance)
    direction = _cone(rng, np.array([1.0, 0.0, 0.0]), c.goal_cone_deg)
    goal = distance * direction
    velocity = v0 * _cone(rng, direction, c.velocity_cone_deg)
    jitter = math.radians(c.attitude_jitter_deg)
    quat = _euler_quat(*rng.uniform(-jitter, jitter, size=3))

    helper = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = _unit(np.cross(direction, helper))
    e2 = np.cross(direction, e1)
    obstacles: list[Obstacle] = []
    goal_t = tuple(float(x) for x in goal)
    for i in range(n):
        for _ in range(c.max_tries):
            shape = c.shapes[int(rng.integers(len(c.shapes)))]
            scale = float(rng.uniform(*c.obstacle_scale))
            size = _obstacle_size(rng, shape, scale)
            along = rng.uniform(*c.along_range) * distance
            if rng.uniform() < c.on_line_prob:
                offset = rng.uniform(0.0, c.on_line_offset * scale)
            else:
                offset = rng.uniform(scale, c.corridor_halfwidth + scale)
            angle = rng.uniform(0.0, 2.0 * math.pi)
            center = along * direction + offset * (math.cos(angle) * e1 + math.sin(angle) * e2)
            ob = Obstacle(
                shape=shape,
                center=tuple(float(x) for x in center),
                size=size,
                quat=_random_quat(rng),
                rgba=_rock_rgba(rng),
            )
            if (
                clearance([ob], (0.0, 0.0, 0.0)) >= c.start_clearance
                and clearance([ob], goal_t) >= c.goal_radius + c.goal_clearance
            ):
                obstacles.append(ob)
                break
        else:
            raise ImpossibleScenario(
                f"could not place obstacle {i} of seed {seed} in {c.max_tries} tries; "
                "lower n_obstacles or obstacle_scale, or raise goal_distance"
            )

    sun = _unit(rng.normal(size=3))
    lighting = Lighting(
        sun_direction=tuple(float(x) for x in sun),
        sun_intensity=float(rng.uniform(*c.sun_intensity)),
        ambient=float(rng.uniform(*c.ambient)),
    )
    return Scenario(
        obstacles=tuple(obstacles),
        goal=goal_t,
        goal_radius=c.goal_radius,
        initial_velocity=tuple(float(x) for x in velocity),
        initial_quat=tuple(float(x) for x in quat),
        lighting=lighting,
        seed=int(seed),
    )
