"""The oracles' true dynamics on the dynamic tier: a rollout through the episode's body, fault and
CW terms lands where the simulator flies the same thrusts, and the nominal body does not."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from orbitdata.fly.pilot import Task
from orbitdata.scenario import ScenarioConfig, sample_scenario
from orbitdata.scenario.dynamics import BodyParameters, ThrusterFault
from orbitdata.sim import CubeSatEnv, SimConfig
from orbitmodel.plan.config import planner_config
from orbitmodel.plan.dynamics import RigidBodyDynamics
from orbitmodel.plan.factory import build_pilot
from orbitmodel.plan.true_body import EpisodeBodyDynamics

DYNAMIC = ScenarioConfig.for_tier("dynamic")
STEPS = 40


def faulty_episode():
    """Empty space, thruster 0 off from frame 10, a heavy off-centre body, and a mean motion large
    enough for the CW terms to show within the rollout."""
    base = sample_scenario(3, DYNAMIC)
    dyn = replace(
        base.dynamics,
        debris=(),
        cw=True,
        mean_motion=0.05,
        body=BodyParameters(mass_scale=1.3, inertia_scale=(1.4, 0.8, 1.1), com_offset=(0.01, -0.008, 0.005)),
        fault=ThrusterFault("off", 0, 0.0, onset_step=10),
    )
    return replace(base, obstacles=(), dynamics=dyn, initial_velocity=(0.5, 0.1, 0.0), goal=(60.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def flown():
    """The simulator's states under a fixed sequence of thrusts (seeded), from the episode's start."""
    scn = faulty_episode()
    actions = np.random.default_rng(0).uniform(0.0, 0.1, (STEPS, 8))  # gentle: the body stays below the tumbling rate
    env = CubeSatEnv(SimConfig(render=False), DYNAMIC)
    obs, _ = env.reset(options={"scenario": scn})
    states = [obs["state"]]
    for a in actions:
        obs, _, terminated, truncated, _ = env.step(a)
        assert not (terminated or truncated)
        states.append(obs["state"])
    env.close()
    return scn, actions, np.array(states)


def imagined(dynamics, state0, actions, frame=0):
    for _ in range(frame + 1):
        dynamics.observe({}, None)
    return dynamics.rollout(torch.as_tensor(state0), torch.as_tensor(actions, dtype=torch.float32)[None])[0].numpy()


def errors(states, truth):
    return np.abs(states[:, :3] - truth[:, :3]).max(), np.abs(states[:, 12:15] - truth[:, 12:15]).max()


def test_the_episode_body_flies_where_the_simulator_does_and_the_nominal_one_does_not(flown):
    scn, actions, truth = flown
    sim = SimConfig(render=False)
    exact = imagined(EpisodeBodyDynamics(scn.dynamics, sim, substeps=sim.substeps), truth[0], actions)
    position, rate = errors(exact, truth[1:])
    assert position < 1e-5 and rate < 1e-4  # the simulator's own scheme: float32 rounding only
    coarse = imagined(EpisodeBodyDynamics(scn.dynamics, sim, substeps=1), truth[0], actions)
    assert errors(coarse, truth[1:])[0] < 0.01  # one Euler step per control step: millimetres over 1.6 s
    nominal = imagined(EpisodeBodyDynamics(scn.dynamics, sim, substeps=sim.substeps, nominal=True), truth[0], actions)
    position, rate = errors(nominal, truth[1:])
    assert position > 0.02 and rate > 1.0  # the dead thruster and the heavier, skewed body
    static = RigidBodyDynamics(sim, substeps=sim.substeps).rollout(
        torch.as_tensor(truth[0]), torch.as_tensor(actions, dtype=torch.float32)[None]
    )[0]
    assert errors(static.numpy(), truth[1:])[0] > 0.01  # the static tier's model: no fault, body or CW


def test_the_fault_starts_at_its_frame_counted_from_the_reset(flown):
    """A rollout from frame 20 (past the onset) through the true body lands where the simulator
    went from frame 20; one that believes it is at frame 0 meets the fault ten frames late."""
    scn, actions, truth = flown
    sim = SimConfig(render=False)
    later = imagined(EpisodeBodyDynamics(scn.dynamics, sim, sim.substeps), truth[20], actions[20:], frame=20)
    assert errors(later, truth[21:])[0] < 1e-5
    early = imagined(EpisodeBodyDynamics(scn.dynamics, sim, sim.substeps), truth[5], actions[5:], frame=0)
    late = imagined(EpisodeBodyDynamics(scn.dynamics, sim, sim.substeps), truth[5], actions[5:], frame=5)
    assert errors(late, truth[6:])[0] < 1e-5 and errors(early, truth[6:])[0] > 1e-3


def test_several_episodes_in_one_call_each_through_its_own_body(flown):
    scn, actions, truth = flown
    sim = SimConfig(render=False)
    true, nominal = EpisodeBodyDynamics(scn.dynamics, sim), EpisodeBodyDynamics(scn.dynamics, sim, nominal=True)
    a = torch.as_tensor(np.stack([actions, actions[::-1]]), dtype=torch.float32)  # (2, H, 8)
    s0 = torch.as_tensor(truth[0])
    for d in (true, nominal):
        d.observe({}, None)
    both = EpisodeBodyDynamics.rollout_many([true, nominal], [s0, s0], [a, a[:1]])
    assert [tuple(x.shape) for x in both] == [(2, STEPS, 16), (1, STEPS, 16)]
    assert torch.equal(both[0], true.rollout(s0, a)) and torch.equal(both[1], nominal.rollout(s0, a[:1]))


def test_the_oracle_plans_each_dynamic_episode_with_its_body_and_the_static_tier_with_the_rigid_body():
    scn = faulty_episode()
    task = Task(goal=scn.goal, goal_radius=0.5, initial_velocity=scn.initial_velocity, seed=3)
    for body, nominal in (("true", False), ("nominal", True)):
        pilot, _ = build_pilot("oracle-true", None, planner_config("cpu", obstacle_motion="true", body=body))
        pilot.reset(task, scenario=scn)
        assert isinstance(pilot.dynamics, EpisodeBodyDynamics) and pilot.dynamics.nominal is nominal
        assert pilot.fork().dynamics is not pilot.dynamics
        static = sample_scenario(3, ScenarioConfig())
        pilot.config = planner_config("cpu", body=body)
        pilot.reset(task, scenario=static)
        assert isinstance(pilot.dynamics, RigidBodyDynamics)


def test_the_camera_oracles_plan_with_the_episodes_body_and_never_hold_its_debris():
    """oracle-true-dyn-sensor (and -depth) see the debris through the camera alone, but plan a
    dynamic-tier episode with its own body and fault, as their name says, or the design's."""
    scn = faulty_episode()
    moving = sample_scenario(3, DYNAMIC)
    assert moving.obstacles and moving.dynamics.debris
    task = Task(goal=scn.goal, goal_radius=0.5, initial_velocity=scn.initial_velocity, seed=3)
    for body, nominal in (("true", False), ("nominal", True)):
        pilot, _ = build_pilot(
            "oracle-true-dyn-sensor", None, planner_config("cpu", obstacle_motion="tracker", body=body)
        )
        assert pilot.privileged and type(pilot).privileged is False  # handed the scenario, not the obstacles
        for episode in (scn, moving):
            pilot.reset(task, scenario=episode)
            assert isinstance(pilot.dynamics, EpisodeBodyDynamics) and pilot.dynamics.nominal is nominal
            assert pilot._true is None and not hasattr(pilot.dynamics, "record")
        pilot.reset(task)  # no scenario: the design's body
        assert isinstance(pilot.dynamics, RigidBodyDynamics)
    fitted, _ = build_pilot("oracle-true-dyn-sensor", None, planner_config("cpu", body="fitted"))
    own = fitted.dynamics
    fitted.reset(task, scenario=scn)
    assert fitted.dynamics is own  # a body fitted to its own history reads no record
