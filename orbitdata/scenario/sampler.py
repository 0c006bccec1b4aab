"""Draw a random episode world as a pure function of (seed, settings).

``ImpossibleScenario`` is re-exported here, where callers have always found it.
"""

from __future__ import annotations

import math

import numpy as np

from orbitdata.scenario.config import DYNAMIC, ScenarioConfig
from orbitdata.scenario.draws import draw_start, obstacle_size, random_quat, rock_rgba, unit
from orbitdata.scenario.dynamic_sampler import sample_dynamic
from orbitdata.scenario.geometry import clearance
from orbitdata.scenario.spec import ImpossibleScenario, Lighting, Obstacle, Scenario
from orbitdata.seeding import rng as make_rng


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

    ``config.tier`` picks the sampler: the static scenes below, or the dynamic tier's
    (:func:`~orbitdata.scenario.dynamic_sampler.sample_dynamic`).

    ``n_obstacles`` and ``speed`` override the random draw (the evaluation grid fixes them).
    Obstacles that would overlap the start or block the goal are redrawn from the same
    generator, so the result stays deterministic.
    """
    rng = make_rng(seed, "scenario")
    c = config
    start = draw_start(rng, c, n_obstacles, speed)
    if c.tier == DYNAMIC:
        return sample_dynamic(seed, c, rng, start)
    n, distance, direction, goal = start.n_obstacles, start.distance, start.direction, start.goal

    helper = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = unit(np.cross(direction, helper))
    e2 = np.cross(direction, e1)
    obstacles: list[Obstacle] = []
    goal_t = tuple(float(x) for x in goal)
    for i in range(n):
        for _ in range(c.max_tries):
            shape = c.shapes[int(rng.integers(len(c.shapes)))]
            scale = float(rng.uniform(*c.obstacle_scale))
            size = obstacle_size(rng, shape, scale)
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
                quat=random_quat(rng),
                rgba=rock_rgba(rng),
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

    sun = unit(rng.normal(size=3))
    lighting = Lighting(
        sun_direction=tuple(float(x) for x in sun),
        sun_intensity=float(rng.uniform(*c.sun_intensity)),
        ambient=float(rng.uniform(*c.ambient)),
    )
    return Scenario(
        obstacles=tuple(obstacles),
        goal=goal_t,
        goal_radius=c.goal_radius,
        initial_velocity=tuple(float(x) for x in start.velocity),
        initial_quat=tuple(float(x) for x in start.quat),
        lighting=lighting,
        seed=int(seed),
    )
