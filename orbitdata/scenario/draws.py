"""Random draws shared by the tiers' samplers: directions, attitudes, obstacle sizes and colours.

Each takes the generator it draws from; the order of draws inside each is part of the episodes'
bytes, so these are moved, never rewritten.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from orbitdata.scenario.config import MAX_OBSTACLES, ScenarioConfig


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def random_quat(rng: np.random.Generator) -> tuple[float, ...]:
    q = rng.normal(size=4)
    q = q / np.linalg.norm(q)
    return tuple(float(x) for x in (q if q[0] >= 0 else -q))


def cone(rng: np.random.Generator, axis: np.ndarray, max_deg: float) -> np.ndarray:
    """A unit vector within ``max_deg`` of ``axis``, uniform over the spherical cap."""
    axis = unit(axis)
    cos_max = math.cos(math.radians(max_deg))
    cos_t = 1.0 - rng.uniform() * (1.0 - cos_max)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = unit(np.cross(axis, helper))
    e2 = np.cross(axis, e1)
    phi = rng.uniform(0.0, 2.0 * math.pi)
    return cos_t * axis + sin_t * (math.cos(phi) * e1 + math.sin(phi) * e2)


def euler_quat(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def obstacle_size(rng: np.random.Generator, shape: str, scale: float) -> tuple[float, float, float]:
    if shape == "sphere":
        return (scale, 0.0, 0.0)
    if shape in ("ellipsoid", "box"):
        dims = scale * rng.uniform(0.6, 1.0, size=3)
        if shape == "box":
            dims = dims * 0.8  # a box's corners reach sqrt(3) times its half-extent
        return tuple(float(x) for x in dims)
    # capsule / cylinder: (radius, half-length)
    return (float(scale * rng.uniform(0.5, 0.8)), float(scale * rng.uniform(0.6, 1.0)), 0.0)


def rock_rgba(rng: np.random.Generator) -> tuple[float, float, float, float]:
    grey = rng.uniform(0.35, 0.8)
    warm = rng.uniform(0.0, 0.2)
    return (float(min(1.0, grey * (1 + warm))), float(grey), float(grey * (1 - warm)), 1.0)


@dataclass(frozen=True)
class Start:
    """What every tier draws first: the obstacle count, the goal and the CubeSat's initial motion."""

    n_obstacles: int
    speed: float  # m/s, v0
    distance: float  # m, start to goal
    direction: np.ndarray  # (3,) unit, start to goal
    goal: np.ndarray  # (3,) m
    velocity: np.ndarray  # (3,) m/s, world frame
    quat: tuple[float, ...]  # (w, x, y, z) initial attitude


def draw_start(
    rng: np.random.Generator, c: ScenarioConfig, n_obstacles: int | None = None, speed: float | None = None
) -> Start:
    """The first draws of an episode; ``n_obstacles`` and ``speed`` override theirs (the grid fixes them)."""
    n = int(rng.integers(c.n_obstacles[0], c.n_obstacles[1] + 1))
    if n_obstacles is not None:
        if (
            isinstance(n_obstacles, bool)
            or not isinstance(n_obstacles, numbers.Integral)
            or not 0 <= n_obstacles <= MAX_OBSTACLES
        ):
            raise ValueError(f"n_obstacles must be a whole number from 0 to {MAX_OBSTACLES}, got {n_obstacles!r}")
        n = int(n_obstacles)
    v0 = float(rng.uniform(*c.speed))
    if speed is not None:
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed must be a finite non-negative number, got {speed}")
        v0 = float(speed)

    distance = rng.uniform(*c.goal_distance)
    direction = cone(rng, np.array([1.0, 0.0, 0.0]), c.goal_cone_deg)
    goal = distance * direction
    velocity = v0 * cone(rng, direction, c.velocity_cone_deg)
    jitter = math.radians(c.attitude_jitter_deg)
    quat = euler_quat(*rng.uniform(-jitter, jitter, size=3))
    return Start(n, v0, float(distance), direction, goal, velocity, quat)
