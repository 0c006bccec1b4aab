"""Draw a dynamic-tier episode: drifting, tumbling debris aimed at the nominal flight, the orbit,
the body, a thruster fault and the sensing, each from its own stream of the episode's seed.

The world frame is the Hill frame at the start (:mod:`orbitdata.scenario.motion`). Each draw
takes the same number of values whatever it yields, so changing one probability never shifts
another draw. Debris that no pilot could escape is redrawn and counted
(``Dynamics.unsurvivable_draws``).
"""

from __future__ import annotations

import math

import numpy as np

from orbitdata.scenario.config import DynamicConfig, ScenarioConfig
from orbitdata.scenario.draws import Start, obstacle_size, random_quat, rock_rgba, unit
from orbitdata.scenario.dynamics import BodyParameters, DebrisMotion, Dynamics, Sensing, ThrusterFault
from orbitdata.scenario.geometry import clearance, signed_distance
from orbitdata.scenario.motion import free_motion, nominal_flight, tumble
from orbitdata.scenario.spec import ImpossibleScenario, Lighting, Obstacle, Scenario
from orbitdata.schema import ACTION_DIM, DT
from orbitdata.seeding import rng as make_rng

GOAL_CHECK_EVERY = 5  # control steps between the checks of debris against the goal region (0.2 s)


def _frame(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across ``direction``, as the static sampler spans its corridor."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = unit(np.cross(direction, helper))
    return e1, np.cross(direction, e1)


def unsurvivable(ob: Obstacle, velocity, initial_velocity, escape_accel: float, n: float, times: np.ndarray) -> bool:
    """Whether the piece (moving at ``velocity`` m/s from its pose at t = 0) fills, at some time in
    ``times``, every point the CubeSat could reach by then.

    The CubeSat drifts freely from the start at ``initial_velocity`` (under the CW terms when
    n > 0); a pilot that accelerates at most ``escape_accel`` (m/s^2) ends within 0.5 a t^2 of
    that drift. If the piece's inscribed sphere holds that whole ball, every such pilot collides.
    """
    drift, _ = free_motion((0.0, 0.0, 0.0), initial_velocity, times, n)
    centres, _ = free_motion(ob.center, velocity, times, n)
    reach = 0.5 * escape_accel * times**2
    return bool(np.any(np.linalg.norm(centres - drift, axis=1) + reach <= ob.inscribed_radius))


def _goal_stays_clear(ob: Obstacle, motion: DebrisMotion, goal, needed: float, n: float, times: np.ndarray) -> bool:
    centres, _ = free_motion(ob.center, motion.velocity, times, n)
    quats = tumble(ob.quat, motion.angular_velocity, times)
    for centre, quat in zip(centres, quats):
        moved = Obstacle(ob.shape, tuple(centre), ob.size, tuple(quat), ob.rgba)
        if signed_distance(moved, goal) < needed:
            return False
    return True


def _draw_debris(
    rng: np.random.Generator, ob: Obstacle, scale: float, start: Start, c: ScenarioConfig, n: float
) -> tuple[Obstacle, DebrisMotion]:
    """One try: where the piece starts and how it moves (intercepting, or drifting in the corridor)."""
    d = c.dynamic
    direction = start.direction
    e1, e2 = _frame(direction)
    intercept = bool(rng.uniform() < d.intercept_prob)
    speed = float(rng.uniform(*d.debris_speed))
    rate = math.radians(float(rng.uniform(*d.tumble_deg_s)))
    spin_axis = unit(rng.normal(size=3))
    along_fraction = float(rng.uniform(*d.intercept_along))
    miss = d.intercept_miss * math.sqrt(float(rng.uniform()))  # uniform over the disc
    miss_angle, across_angle = rng.uniform(0.0, 2.0 * math.pi, size=2)
    tilt = float(rng.uniform(-0.5, 0.5))  # along-track share of the crossing direction
    jitter = float(rng.uniform(-d.intercept_jitter, d.intercept_jitter))
    drift_along = float(rng.uniform(*c.along_range)) * start.distance
    drift_offset = float(rng.uniform(scale, c.corridor_halfwidth + scale))
    drift_angle = float(rng.uniform(0.0, 2.0 * math.pi))
    drift_direction = unit(rng.normal(size=3))

    omega = tuple(float(x) for x in rate * spin_axis)
    if intercept:
        v_nominal = max(start.speed, d.nominal_speed)
        t_star = along_fraction * start.distance / v_nominal
        aim = nominal_flight(start.goal, v_nominal, [t_star])[0] + miss * (
            math.cos(miss_angle) * e1 + math.sin(miss_angle) * e2
        )
        crossing = max(0.0, t_star + jitter)
        across = math.cos(across_angle) * e1 + math.sin(across_angle) * e2
        v_cross = speed * unit(across + tilt * direction)
        p0, v0 = (x[0] for x in free_motion(aim, v_cross, [-crossing], n))  # back from the crossing to t = 0
        motion = DebrisMotion(
            velocity=tuple(float(x) for x in v0),
            angular_velocity=omega,
            intercept=True,
            t_star=float(t_star),
            crossing_time=float(crossing),
            aim=tuple(float(x) for x in aim),
        )
    else:
        p0 = drift_along * direction + drift_offset * (math.cos(drift_angle) * e1 + math.sin(drift_angle) * e2)
        motion = DebrisMotion(velocity=tuple(float(x) for x in speed * drift_direction), angular_velocity=omega)
    return Obstacle(ob.shape, tuple(float(x) for x in p0), ob.size, ob.quat, ob.rgba), motion


def _fault(rng: np.random.Generator, d: DynamicConfig) -> ThrusterFault:
    faulty = rng.uniform() < d.fault_prob
    kind = d.fault_kinds[int(rng.integers(len(d.fault_kinds)))]
    thruster = int(rng.integers(ACTION_DIM))
    scaled, stuck = float(rng.uniform(*d.fault_scale)), float(rng.uniform(*d.fault_stuck))
    at_start = rng.uniform() < d.fault_at_start_prob
    onset = float(rng.uniform(*d.fault_onset))
    if not faulty:
        return ThrusterFault()
    level = {"off": 0.0, "scaled": scaled, "stuck": stuck}[kind]
    return ThrusterFault(kind, thruster, level, 0 if at_start else int(round(onset / DT)))


def _body(rng: np.random.Generator, d: DynamicConfig) -> BodyParameters:
    mass = float(rng.uniform(*d.mass_scale))
    inertia = rng.uniform(*d.inertia_scale, size=3)
    com = unit(rng.normal(size=3)) * float(rng.uniform(*d.com_offset))
    return BodyParameters(mass, tuple(float(x) for x in inertia), tuple(float(x) for x in com))


def sample_dynamic(seed: int, c: ScenarioConfig, rng: np.random.Generator, start: Start) -> Scenario:
    """The dynamic-tier world of episode ``seed``, after ``start`` was drawn from ``rng`` (its scenario stream).

    The scenario stream goes on to the debris' shapes, attitudes and colours and the sun; the
    debris' placement and motion, the orbit, the body, the fault and the sensing each have their own.
    """
    d = c.dynamic
    cw = bool(make_rng(seed, "orbit").uniform() < d.cw_prob)
    n = d.mean_motion if cw else 0.0
    shapes = []  # (the piece at the origin, its scale): placed below
    for _ in range(start.n_obstacles):
        shape = c.shapes[int(rng.integers(len(c.shapes)))]
        scale = float(rng.uniform(*c.obstacle_scale))
        size = obstacle_size(rng, shape, scale)
        shapes.append((Obstacle(shape, (0.0, 0.0, 0.0), size, random_quat(rng), rock_rgba(rng)), scale))
    sun = unit(rng.normal(size=3))
    sun_intensity, ambient = float(rng.uniform(*c.sun_intensity)), float(rng.uniform(*c.ambient))

    sensing_rng = make_rng(seed, "sensing")
    eclipse = bool(sensing_rng.uniform() < d.eclipse_prob)
    sensing = Sensing(d.rgb_noise, float(sensing_rng.uniform(*d.depth_dropout)), eclipse, d.onboard_light)
    lighting = Lighting(
        sun_direction=tuple(float(x) for x in sun),
        sun_intensity=0.0 if eclipse else sun_intensity,
        ambient=d.eclipse_ambient if eclipse else ambient,
    )

    debris_rng = make_rng(seed, "debris")
    times = np.arange(int(round(d.horizon / DT)) + 1) * DT  # s, the control grid over the horizon
    goal_times = times[::GOAL_CHECK_EVERY]
    goal = tuple(float(x) for x in start.goal)
    obstacles, motions, rejected = [], [], 0
    for i, (ob, scale) in enumerate(shapes):
        for _ in range(d.max_tries):
            placed, motion = _draw_debris(debris_rng, ob, scale, start, c, n)
            if clearance([placed], (0.0, 0.0, 0.0)) < c.start_clearance or not _goal_stays_clear(
                placed, motion, goal, c.goal_radius + c.goal_clearance, n, goal_times
            ):
                continue
            if unsurvivable(placed, motion.velocity, start.velocity, d.escape_accel, n, times):
                rejected += 1
                continue
            obstacles.append(placed)
            motions.append(motion)
            break
        else:
            raise ImpossibleScenario(
                f"could not place debris {i} of seed {seed} in {d.max_tries} tries; lower n_obstacles, "
                "obstacle_scale or dynamic.debris_speed, or raise goal_distance"
            )

    dynamics = Dynamics(
        debris=tuple(motions),
        cw=cw,
        mean_motion=d.mean_motion,
        body=_body(make_rng(seed, "body"), d),
        fault=_fault(make_rng(seed, "fault"), d),
        sensing=sensing,
        unsurvivable_draws=rejected,
    )
    return Scenario(
        obstacles=tuple(obstacles),
        goal=goal,
        goal_radius=c.goal_radius,
        initial_velocity=tuple(float(x) for x in start.velocity),
        initial_quat=tuple(float(x) for x in start.quat),
        lighting=lighting,
        seed=int(seed),
        dynamics=dynamics,
    )
