"""The dynamic tier's pilots: the MPPI expert that knows the debris' motion, the body and the fault,
and ``expert-snapshot``, the static expert planning on the debris as it stands at t = 0."""

import dataclasses
import hashlib

import numpy as np
import pytest

from orbitdata.fly import FlightConfig, Pilot, fly_episode, list_pilots, make_pilot
from orbitdata.fly.pilots.body_model import BodyModel
from orbitdata.fly.pilots.config import DynamicExpertConfig
from orbitdata.fly.pilots.debris_field import DebrisField
from orbitdata.fly.pilots.dynamic_expert import DynamicExpertPilot
from orbitdata.fly.pilots.expert import ExpertPilot
from orbitdata.fly.pilots.snapshot import SnapshotExpertPilot
from orbitdata.scenario.config import ScenarioConfig
from orbitdata.scenario.dynamics import BodyParameters, DebrisMotion, Dynamics, ThrusterFault
from orbitdata.scenario.geometry import clearance, signed_distance
from orbitdata.scenario.sampler import sample_scenario
from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.schema import DT
from orbitdata.sim import CubeSatEnv, SimConfig
from orbitdata.state import rot6d_to_matrix

DYNAMIC = FlightConfig(sim=SimConfig(render=False), scenario=ScenarioConfig.for_tier("dynamic"))
DEAD = 2  # the thruster that is off in the faulty scenes below


@pytest.fixture(scope="module")
def env():
    e = CubeSatEnv(DYNAMIC.sim, DYNAMIC.scenario)
    yield e
    e.close()


def crossing_scene() -> Scenario:
    """A 0.6 m sphere drifting across the straight path: it is at x = 5 m, on the line, at 2.5 s,
    when a straight 2 m/s flight gets there; at t = 0 it is 2 m off the line."""
    debris = Obstacle("sphere", center=(5.0, 2.0, 0.0), size=(0.6, 0.0, 0.0))
    motion = DebrisMotion(velocity=(0.0, -0.8, 0.0), intercept=True, t_star=2.5, crossing_time=2.5, aim=(5.0, 0.0, 0.0))
    return Scenario(
        obstacles=(debris,),
        goal=(10.0, 0.0, 0.0),
        initial_velocity=(2.0, 0.0, 0.0),
        dynamics=Dynamics(debris=(motion,)),
    )


def faulty_scene() -> Scenario:
    """A seeded scene of the tier, its body heavier with the centre of mass 2 cm off and thruster
    ``DEAD`` off from the start."""
    scn = sample_scenario(5, DYNAMIC.scenario, 3, 1.0)
    body = BodyParameters(mass_scale=1.2, inertia_scale=(0.8, 1.2, 1.1), com_offset=(0.015, -0.01, 0.008))
    return dataclasses.replace(
        scn, dynamics=dataclasses.replace(scn.dynamics, body=body, fault=ThrusterFault("off", DEAD, 0.0, 0))
    )


def withheld(scn: Scenario) -> Scenario:
    """The scene as a pilot that is not told the body and the fault sees it."""
    return dataclasses.replace(
        scn, dynamics=dataclasses.replace(scn.dynamics, body=BodyParameters(), fault=ThrusterFault())
    )


class Told(Pilot):
    """Flies ``pilot`` but resets it with ``transform(scenario)`` instead of the true scenario."""

    privileged = True

    def __init__(self, pilot, transform):
        self.pilot, self.transform, self.name = pilot, transform, pilot.name

    def reset(self, task, scenario):
        self.pilot.reset(task, scenario=self.transform(scenario))

    def act(self, obs):
        return self.pilot.act(obs)


def test_the_expert_avoids_debris_aimed_at_it_that_a_straight_flight_and_the_snapshot_hit(env):
    scn = crossing_scene()
    assert fly_episode(env, make_pilot("risky", DYNAMIC), seed=0, scenario=scn).outcome == "collision"
    # The snapshot plans around the sphere where it stands at t = 0: off the line, so straight on.
    assert fly_episode(env, make_pilot("expert-snapshot", DYNAMIC), seed=0, scenario=scn).outcome == "collision"
    expert = fly_episode(env, make_pilot("expert", DYNAMIC), seed=0, scenario=scn)
    assert expert.outcome == "success" and expert.min_clearance.min() > 0.1


def test_expert_is_the_tiers_expert_and_the_snapshot_is_registered():
    assert isinstance(make_pilot("expert", DYNAMIC), DynamicExpertPilot)
    assert type(make_pilot("expert")) is ExpertPilot  # the static tier's, unchanged
    assert "expert-snapshot" in list_pilots()
    snapshot = make_pilot("expert-snapshot", DYNAMIC)
    assert isinstance(snapshot, SnapshotExpertPilot) and snapshot.name == "expert-snapshot" and snapshot.privileged
    assert make_pilot("expert", DYNAMIC).name == "expert"  # the dataset's level


def test_the_snapshot_plans_around_the_debris_as_it_stands_at_t0(env):
    scn = sample_scenario(11, DYNAMIC.scenario, 7, 1.0)
    pilot = make_pilot("expert-snapshot", DYNAMIC)
    result = fly_episode(env, pilot, seed=11, scenario=scn)
    assert result.scenario == scn and pilot.plan.solved
    path = pilot.trajectory.points  # its reference, every 5 cm
    inflation = DYNAMIC.sim.cubesat.bounding_radius  # the planner's margin comes on top
    at_start = scn.obstacles_at(0.0)
    assert min(clearance(at_start, p) for p in path) > inflation
    # ... and nothing else: the debris as it will be when the path gets there is not avoided.
    later = scn.obstacles_at(2.0)
    assert min(clearance(later, p) for p in path) < min(clearance(at_start, p) for p in path)


def _digest(result) -> str:
    return hashlib.sha256(np.ascontiguousarray(result.actions).tobytes() + result.states.tobytes()).hexdigest()


def test_the_expert_is_seeded_same_episode_same_actions(env):
    a = fly_episode(env, make_pilot("expert", DYNAMIC), seed=3, n_obstacles=7, speed=3.0)
    b = fly_episode(env, make_pilot("expert", DYNAMIC), seed=4, n_obstacles=7, speed=3.0)
    pilot = make_pilot("expert", DYNAMIC)  # one pilot, two flights: reset starts afresh
    fly_episode(env, pilot, seed=4, n_obstacles=7, speed=3.0)
    c = fly_episode(env, pilot, seed=3, n_obstacles=7, speed=3.0)
    assert _digest(a) == _digest(c) != _digest(b)
    assert a.actions.min() >= 0 and a.actions.max() <= 1
    assert pilot.metadata()["planner"]["iterations"] > 0


def test_the_expert_reads_the_fault_it_never_commands_a_dead_thruster_unless_withheld(env):
    scn = faulty_scene()
    quiet = DynamicExpertConfig(noise_std=0.0)
    told = fly_episode(env, DynamicExpertPilot(quiet), seed=5, scenario=scn)
    blind = fly_episode(env, Told(DynamicExpertPilot(quiet), withheld), seed=5, scenario=scn)
    assert told.outcome == "success"
    assert np.all(told.actions[:, DEAD] == 0.0)
    assert blind.actions[:, DEAD].max() > 0.1  # it fires a thruster that gives nothing
    assert not np.array_equal(told.actions[: len(blind.actions)], blind.actions[: len(told.actions)])


def _predicted_and_flown(env, scn: Scenario, model: BodyModel, steps: int = 40):
    """The model's rollout of a constant acceleration command from the start, and the flight that
    command gives in the simulator (the same law at every real state), until the episode ends."""
    obs, _ = env.reset(options={"scenario": scn})
    accel, goal = np.array([1.0, 1.5, -0.5]), np.asarray(scn.goal)

    def state(obs):
        s = obs["state"].astype(np.float64)
        R = rot6d_to_matrix(s[6:12])
        return s[0:3], R @ s[3:6], R, s[12:15], s[15]

    *start, fuel = state(obs)
    predicted = model.rollout(tuple(start), np.tile(accel, (1, steps, 1)), goal, 0, fuel).position[0]
    flown = []
    for t in range(steps):
        p, v, R, w, fuel = (np.asarray(x)[None] for x in state(obs))
        mass, inertia = model.mass_properties(float(fuel[0]))
        x, xv = model.centre_of_mass(p, v, R, w)
        obs, _, terminated, truncated, _ = env.step(model.command(x, xv, R, w, accel[None], goal, t, mass, inertia)[0])
        flown.append(obs["state"][:3])
        if terminated or truncated:  # a blind command can spin the body past the tier's rate limit
            break
    return predicted[: len(flown)], np.array(flown)


def test_the_expert_reads_the_body_and_the_fault_it_predicts_its_flight_the_blind_model_does_not(env):
    scn = faulty_scene()
    told = np.linalg.norm(np.subtract(*_predicted_and_flown(env, scn, BodyModel(dynamics=scn.dynamics))), axis=1)
    blind = np.linalg.norm(
        np.subtract(*_predicted_and_flown(env, scn, BodyModel(dynamics=withheld(scn).dynamics))), axis=1
    )
    assert told.max() < 0.1  # m over 1.6 s of flight
    assert blind.max() > 3 * told.max()


@pytest.mark.parametrize("shape", ["sphere", "ellipsoid", "box", "capsule", "cylinder"])
def test_the_debris_field_scores_a_point_against_the_debris_where_it_is_then(shape):
    rng = np.random.default_rng(0)
    quat = rng.normal(size=4)
    ob = Obstacle(shape, center=(3.0, 0.5, -0.2), size=(0.5, 0.3, 0.4), quat=tuple(quat / np.linalg.norm(quat)))
    motion = DebrisMotion(velocity=(0.2, -0.6, 0.3), angular_velocity=(0.3, 0.1, -0.4))
    scn = Scenario(
        obstacles=(ob,), goal=(9.0, 0.0, 0.0), dynamics=Dynamics(debris=(motion,), cw=True, mean_motion=0.00113)
    )
    field = DebrisField(scn, frames=60)
    points = ob.center + rng.normal(0.0, 0.8, (4, 12, 3))  # (K, H, 3), row h at frame 10 + 3 h
    got = field.clearance(points, 10, stride=3)
    for k in range(4):
        for h in range(12):
            moved = scn.obstacles_at((10 + 3 * h) * DT)[0]
            assert got[k, h] == pytest.approx(signed_distance(moved, points[k, h]), abs=1e-9)


def test_the_expert_settings_are_checked_and_name_the_setting():
    with pytest.raises(ValueError, match="dynamic_expert.samples must be >= 2, got 1"):
        DynamicExpertConfig(samples=1)
    with pytest.raises(ValueError, match="dynamic_expert.temperature must be > 0"):
        DynamicExpertConfig(temperature=0.0)


def test_the_tier_expert_flies_its_configured_settings_and_only_a_dynamic_record_names_them(tmp_path):
    from orbitdata.config import GenerationConfig

    toml = tmp_path / "expert.toml"
    toml.write_text('[scenario]\ntier = "dynamic"\n[pilots.dynamic_expert]\nsamples = 16\nreplan_every = 4\n')
    cfg = GenerationConfig.from_toml(toml)
    pilot = make_pilot("expert", cfg.flight)
    assert isinstance(pilot, DynamicExpertPilot)
    assert (pilot.config.samples, pilot.config.replan_every) == (16, 4)
    assert cfg.to_dict()["pilots"]["dynamic_expert"]["samples"] == 16  # meta/info.json records what flew
    assert GenerationConfig.from_dict(cfg.to_dict()) == cfg
    assert "dynamic_expert" not in GenerationConfig().to_dict()["pilots"]  # the static record is as before
