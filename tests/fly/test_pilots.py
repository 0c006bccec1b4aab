"""The three pilot levels: PD reaches a goal, determinism, and what each level is for."""

import hashlib

import numpy as np
import pytest

from orbitdata.fly import make_pilot
from orbitdata.fly.rollout import fly_episode
from orbitdata.scenario.spec import Lighting, Obstacle, Scenario
from orbitdata.sim import CubeSatEnv, SimConfig


@pytest.fixture(scope="module")
def env():
    e = CubeSatEnv(SimConfig(render=False))
    yield e
    e.close()


def _digest(result) -> str:
    h = hashlib.sha256()
    for arr in (result.states, result.actions, result.collision, result.success):
        h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("level", ["risky", "expert"])
def test_pd_reaches_a_goal_in_free_space(env, level):
    scn = Scenario(obstacles=(), goal=(6.0, 2.0, -1.0), initial_velocity=(0.5, -0.5, 0.0), lighting=Lighting())
    result = fly_episode(env, make_pilot(level), seed=0, scenario=scn)
    assert result.outcome == "success"
    assert np.linalg.norm(result.states[-1, 0:3] - np.array(scn.goal)) <= scn.goal_radius
    assert result.success[-1] and not result.collision.any()


def test_expert_turns_the_camera_towards_travel(env):
    # The goal is to the side of the initial camera axis (+x): the expert yaws towards it.
    scn = Scenario(obstacles=(), goal=(0.0, 8.0, 0.0), initial_velocity=(0.0, 0.0, 0.0), lighting=Lighting())
    result = fly_episode(env, make_pilot("expert"), seed=0, scenario=scn)
    R = result.states[len(result.states) // 2, 6:12].reshape(3, 2)
    camera_axis = R[:, 0]  # first column of R: body x in the world
    assert camera_axis @ np.array([0.0, 1.0, 0.0]) > 0.8


@pytest.mark.parametrize("level", ["expert", "risky", "exploratory"])
def test_each_pilot_is_deterministic_for_a_seed(env, level):
    a = fly_episode(env, make_pilot(level), seed=21, n_obstacles=3, speed=1.5)
    b = fly_episode(env, make_pilot(level), seed=22, n_obstacles=3, speed=1.5)
    c = fly_episode(env, make_pilot(level), seed=21, n_obstacles=3, speed=1.5)
    assert _digest(a) == _digest(c) != _digest(b)
    assert a.actions.min() >= 0 and a.actions.max() <= 1
    np.testing.assert_array_equal(a.actions[-1], 0.0)  # terminal frame: nothing applied


def test_expert_avoids_what_the_risky_pilot_hits(env):
    wall = Obstacle("sphere", center=(5.0, 0.0, 0.0), size=(1.2, 0.0, 0.0))
    scn = Scenario(obstacles=(wall,), goal=(10.0, 0.0, 0.0), initial_velocity=(2.0, 0.0, 0.0), lighting=Lighting())
    assert fly_episode(env, make_pilot("risky"), seed=0, scenario=scn).outcome == "collision"
    expert = fly_episode(env, make_pilot("expert"), seed=0, scenario=scn)
    assert expert.outcome == "success"
    assert expert.pilot_info["planner"]["solved"]
    assert expert.min_clearance.min() > 0.1


def test_exploratory_noise_is_strong_and_correlated(env):
    explo = fly_episode(env, make_pilot("exploratory"), seed=3, n_obstacles=0, speed=1.0)
    risky = fly_episode(env, make_pilot("risky"), seed=3, n_obstacles=0, speed=1.0)
    a = explo.actions[:-1]
    assert a.std() > 2 * risky.actions[:-1].std()
    # Ornstein-Uhlenbeck with tau = 0.6 s at 25 Hz: lag-1 autocorrelation near exp(-0.04/0.6).
    x = a - a.mean(0)
    lag1 = (x[1:] * x[:-1]).sum() / (x * x).sum()
    assert lag1 > 0.6


def test_unknown_level_is_rejected():
    with pytest.raises(ValueError, match="unknown pilot"):
        make_pilot("reckless")


def _rock_between(goal=(8.0, 0.0, 0.0)) -> Scenario:
    rock = Obstacle("sphere", center=(4.0, 0.0, 0.0), size=(1.0, 0.0, 0.0))
    return Scenario(obstacles=(rock,), goal=goal, initial_velocity=(0.5, 0.0, 0.0), lighting=Lighting())


def _task(scn: Scenario, seed: int):
    from orbitdata.fly.pilot import Task

    return Task(goal=scn.goal, goal_radius=scn.goal_radius, initial_velocity=scn.initial_velocity, seed=seed)


def test_other_draws_of_the_expert_plan_the_same_task_anew(env):
    scn = _rock_between()
    own = fly_episode(env, make_pilot("expert"), seed=3, scenario=scn)
    assert _digest(fly_episode(env, make_pilot("expert", plan_draw=0, noise_draw=0), seed=3, scenario=scn)) == _digest(
        own
    )
    plans = {}
    for name, options in {"own": {}, "plan": {"plan_draw": 1}, "noise": {"noise_draw": 1}}.items():
        pilot = make_pilot("expert", **options)
        pilot.reset(_task(scn, 3), scenario=scn)
        plans[name] = pilot.trajectory.points
    assert np.array_equal(plans["noise"], plans["own"])  # another noise draw flies the same plan
    assert plans["plan"].shape != plans["own"].shape or not np.allclose(plans["plan"], plans["own"])
    noisy = fly_episode(env, make_pilot("expert", noise_draw=1), seed=3, scenario=scn)
    assert not np.array_equal(noisy.actions[:5], own.actions[:5])
    for bad in ("x", "-1", "1.5"):
        with pytest.raises(ValueError, match="plan_draw"):
            make_pilot("expert", plan_draw=bad)


def test_the_expert_takes_its_plan_up_again_at_a_recorded_state(env):
    """An expert without thrust noise, handed a state of its own flight, acts as it did there;
    its plan could be there, and could not be a metre to the side."""
    from orbitdata.fly.pilots.config import ExpertConfig
    from orbitdata.fly.pilots.control import Controller
    from orbitdata.fly.pilots.expert import ExpertPilot

    scn = _rock_between()
    quiet = ExpertConfig(noise_std=0.0)
    flown = fly_episode(env, ExpertPilot(quiet, controller=Controller()), seed=3, scenario=scn)
    assert flown.outcome == "success"
    pilot = ExpertPilot(quiet, controller=Controller())
    pilot.reset(_task(scn, 3), scenario=scn)
    for t in range(0, flown.length - 8, 7):  # taken up at frame t, it acts as it did at t .. t+7
        assert pilot.rejoin(flown.states[t]) is not None
        acts = [pilot.act({"state": flown.states[k]}) for k in range(t, t + 8)]
        assert np.allclose(acts, flown.actions[t : t + 8], atol=1e-6), t
    middle = flown.states[flown.length // 2]
    assert all(d < limit for d, limit in zip(pilot.deviation(middle), (0.1, 0.1, 27.0)))
    assert pilot.could_be_at(middle, 0.1, 0.1, 27.0)
    from orbitdata.state import ROT6D, VELOCITY, matrix_to_rot6d, rot6d_to_matrix

    aside, faster, turned = middle.copy(), middle.copy(), middle.copy()
    aside[2] += 1.0  # a metre off the path
    faster[VELOCITY] *= 1.5  # half as fast again as the plan there
    c, s_ = np.cos(np.radians(45)), np.sin(np.radians(45))
    yaw = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    R = rot6d_to_matrix(middle[ROT6D].astype(np.float64))
    turned[ROT6D] = matrix_to_rot6d(yaw @ R)  # the camera 45 degrees off, the same world velocity
    turned[VELOCITY] = (yaw @ R).T @ (R @ middle[VELOCITY].astype(np.float64))
    assert pilot.deviation(aside)[0] > 0.1
    for state, which in ((faster, 1), (turned, 2)):  # off in speed only, in attitude only
        d = pilot.deviation(state)
        assert [x > limit for x, limit in zip(d, (0.1, 0.1, 27.0))] == [k == which for k in range(3)], (which, d)
    for state in (aside, faster, turned):
        assert not pilot.could_be_at(state, 0.1, 0.1, 27.0)
