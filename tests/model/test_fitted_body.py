"""The fitted body: a thrust response fitted to the pilot's own history finds a dead thruster and a
skewed body the nominal design misses, and reads no record to do it."""

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
from orbitmodel.plan.factory import build_pilot
from orbitmodel.plan.fitted_body import FittedBodyDynamics, FittedBodyLearnedDynamics, fit_response, nominal_response

DYNAMIC = ScenarioConfig.for_tier("dynamic")
DEAD = 2  # the thruster that is off from frame 0
STEPS, FIT, AHEAD = 80, 40, 25


def skewed_episode():
    """Empty space, thruster DEAD off from the start, a heavy off-centre body, no CW terms."""
    base = sample_scenario(5, DYNAMIC)
    dyn = replace(
        base.dynamics,
        debris=(),
        cw=False,
        body=BodyParameters(mass_scale=1.2, inertia_scale=(1.2, 0.8, 1.1), com_offset=(0.015, -0.01, 0.005)),
        fault=ThrusterFault("off", DEAD, 0.0, onset_step=0),
    )
    return replace(base, obstacles=(), dynamics=dyn, initial_velocity=(0.2, 0.0, 0.0), goal=(60.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def flown():
    """The simulator's states under seeded random thrusts, gentle enough to stay below the tumbling rate."""
    actions = np.random.default_rng(1).uniform(0.0, 0.02, (STEPS, 8)).astype(np.float32)
    env = CubeSatEnv(SimConfig(render=False), DYNAMIC)
    obs, _ = env.reset(options={"scenario": skewed_episode()})
    states = [obs["state"]]
    for a in actions:
        obs, _, terminated, truncated, _ = env.step(a)
        assert not (terminated or truncated)
        states.append(obs["state"])
    env.close()
    return actions, np.array(states, dtype=np.float32)


def watched(dynamics, states, actions, upto):
    """``dynamics`` after observing frames 0..upto, each with the action that led to it."""
    dynamics.reset()
    for j in range(upto + 1):
        dynamics.observe({"state": states[j]}, actions[j - 1] if j else None)
    return dynamics


def predicted(dynamics, states, actions, t):
    plan = torch.as_tensor(actions[t : t + AHEAD])[None]
    return dynamics.rollout(torch.as_tensor(states[t]), plan)[0].numpy()


def rate_error(states, truth):
    return float(np.abs(states[:, 12:15] - truth[:, 12:15]).max())


def test_the_fit_finds_the_dead_thruster_and_predicts_the_body_the_nominal_design_does_not(flown):
    actions, truth = flown
    sim = SimConfig(render=False)
    fitted = watched(FittedBodyDynamics(sim, frames=FIT, ridge=1e-5), truth, actions, FIT)
    B, prior = fitted.response(), nominal_response(sim, float(truth[FIT, 15]))
    rate = slice(3, 6)
    assert B[DEAD, rate].norm() < 0.1 * prior[DEAD, rate].norm()  # off: it turns the body no more
    live = [i for i in range(8) if i != DEAD]
    assert (B[live, rate].norm(dim=1) > 0.5 * prior[live, rate].norm(dim=1)).all()
    ahead = truth[FIT + 1 : FIT + 1 + AHEAD]
    fit_error = rate_error(predicted(fitted, truth, actions, FIT), ahead)
    nominal = watched(FittedBodyDynamics(sim, frames=FIT, ridge=1e-5), truth, actions, 0)  # no history: the design
    nominal.observe({"state": truth[FIT]}, None)  # a gap: the history starts again at frame FIT
    nominal_error = rate_error(predicted(nominal, truth, actions, FIT), ahead)
    assert fit_error < 0.5 * nominal_error, (fit_error, nominal_error)


def test_without_history_the_fit_is_the_prior_and_a_large_ridge_holds_it_there(flown):
    actions, truth = flown
    prior = nominal_response(SimConfig(render=False), 1.0)
    states = torch.as_tensor(truth[: FIT + 1])
    assert torch.equal(fit_response(states[:1], torch.zeros(0, 8), prior, 1e-5), prior)
    held = fit_response(states, torch.as_tensor(actions[:FIT]), prior, 1e6)
    assert torch.allclose(held, prior, atol=1e-3 * float(prior.abs().max()))


def test_a_gap_in_the_record_restarts_the_history_and_forks_keep_their_own(flown):
    actions, truth = flown
    sim = SimConfig(render=False)
    fitted = watched(FittedBodyDynamics(sim, frames=FIT, ridge=1e-5), truth, actions, FIT)
    twin = fitted.fork()
    twin.observe({"state": truth[0]}, None)
    assert len(fitted._actions) == FIT and len(twin._actions) == 0
    fitted.observe({"state": truth[FIT + 1]}, None)
    assert len(fitted._actions) == 0 and len(fitted._states) == 1
    a = torch.as_tensor(actions[:AHEAD])[None]
    both = FittedBodyDynamics.rollout_many(
        [fitted, twin], [torch.as_tensor(truth[FIT + 1]), torch.as_tensor(truth[0])], [a, a]
    )
    # each through its own fit, and to the last bit what it imagines alone (a lockstep batch's guarantee)
    assert torch.equal(both[0], fitted.rollout(torch.as_tensor(truth[FIT + 1]), a))
    assert torch.equal(both[1], twin.rollout(torch.as_tensor(truth[0]), a))
    assert not torch.allclose(both[0], both[1])
    with pytest.raises(RuntimeError, match="observe"):
        FittedBodyDynamics(sim).rollout(torch.as_tensor(truth[0]), a)


def test_the_pilots_that_plan_with_the_rigid_body_may_fit_it_and_read_no_record():
    scn = skewed_episode()
    task = Task(goal=scn.goal, goal_radius=0.5, initial_velocity=scn.initial_velocity, seed=5)
    pilot, _ = build_pilot("oracle-true", None, planner_config("cpu", obstacle_motion="true", body="fitted"))
    pilot.reset(task, scenario=scn)
    assert isinstance(pilot.dynamics, FittedBodyDynamics) and pilot.fork().dynamics is not pilot.dynamics
    sensing, _ = build_pilot("oracle-true-dyn-sensor", None, planner_config("cpu", body="fitted", fit_frames=20))
    assert isinstance(sensing.dynamics, FittedBodyDynamics) and sensing.dynamics.frames == 20
    with pytest.raises(ValueError, match="fit_frames=0"):
        planner_config("cpu", body="fitted", fit_frames=0)


def test_the_planner_with_the_fitted_body_plans_with_its_states_and_keeps_the_world_model_s_eyes(probed_run, flown):
    """The states the planner's cost reads are the fitted body's; the world model still encodes
    each frame, and rolls no latent out unless the imagined depth needs them."""
    actions, truth = flown
    config = planner_config("cpu", body="fitted", horizon=10, samples=4)
    pilot, _ = build_pilot("planner", probed_run, config)
    assert isinstance(pilot.dynamics, FittedBodyLearnedDynamics) and not pilot.dynamics.imagine
    dyn = pilot.fork().dynamics
    assert dyn.body is not pilot.dynamics.body
    image = np.zeros((pilot.dynamics.model.config.image_size,) * 2 + (3,), np.uint8)
    for j in range(FIT + 1):
        dyn.observe({"image": image, "state": truth[j]}, actions[j - 1] if j else None)
    assert len(dyn._z) and len(dyn.body._actions) == FIT
    dyn.fork()
    assert len(dyn.body._actions) == FIT  # a fork starts empty and leaves this history alone
    plan = torch.as_tensor(actions[FIT : FIT + 10])[None]
    expected = dyn.body.rollout(torch.as_tensor(truth[FIT]), plan)
    assert torch.equal(dyn.rollout(torch.as_tensor(truth[FIT]), plan), expected)
    assert not hasattr(dyn, "imagined_latents")  # no latent was rolled out
    imagining = FittedBodyLearnedDynamics(dyn.model, dyn.probe, dyn.body.fork(), imagine=True)
    for j in range(FIT + 1):
        imagining.observe({"image": image, "state": truth[j]}, actions[j - 1] if j else None)
    assert torch.equal(imagining.rollout(torch.as_tensor(truth[FIT]), plan), expected)
    steps = 10 // imagining.step
    assert tuple(imagining.imagined_latents.shape) == (1, steps, dyn.model.config.latent_dim)
    with pytest.raises(ValueError, match="oracle-learned-dyn"):
        build_pilot("oracle-learned-dyn", probed_run, planner_config("cpu", body="fitted", obstacle_motion="true"))
