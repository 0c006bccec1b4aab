"""A body spun up by a faulty thruster: on the dynamic tier the episode ends ``tumbling`` at the
tier's rate limit, and no flight ever goes on from a state that MuJoCo reset."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from orbitdata import schema as S
from orbitdata.fly.pilot import Pilot
from orbitdata.fly.registry import make_pilot
from orbitdata.fly.rollout import fly_episode
from orbitdata.scenario.config import DynamicConfig, ScenarioConfig
from orbitdata.scenario.dynamics import ThrusterFault
from orbitdata.scenario.sampler import sample_scenario
from orbitdata.sim import CubeSatEnv, SimConfig
from orbitdata.sim.env import INSTABILITY_WARNINGS, SimulationUnstable
from orbitdata.state import ANGULAR_VELOCITY, POSITION

ONSET = 10  # frame at which the stuck thruster starts firing


class Coast(Pilot):
    """Commands no thrust at all: whatever the body does, the fault does."""

    name = "coast"

    def reset(self, task) -> None:
        pass

    def act(self, obs) -> np.ndarray:
        return np.zeros(S.ACTION_DIM)


def dynamic_env(max_body_rate: float = DynamicConfig.max_body_rate) -> CubeSatEnv:
    config = ScenarioConfig.for_tier("dynamic", dynamic=DynamicConfig(max_body_rate=max_body_rate))
    return CubeSatEnv(SimConfig(render=False), config)


def stuck_on(seed: int = 3):
    """A dynamic-tier scenario whose thruster 0 is stuck full on from frame ``ONSET``: its torque
    spins the body up by tens of rad/s every second."""
    scn = sample_scenario(seed, ScenarioConfig.for_tier("dynamic"))
    fault = ThrusterFault("stuck", thruster=0, level=1.0, onset_step=ONSET)
    return dataclasses.replace(scn, dynamics=dataclasses.replace(scn.dynamics, fault=fault))


def rates(states: np.ndarray) -> np.ndarray:
    return np.linalg.norm(states[:, ANGULAR_VELOCITY], axis=1)  # (L,) rad/s


def assert_never_reset(env: CubeSatEnv, states: np.ndarray) -> None:
    """MuJoCo warned of no instability, and the record shows no jump back to the start at rest."""
    for warning in INSTABILITY_WARNINGS:
        assert env.data.warning[warning].number == 0, warning.name
    jumps = np.linalg.norm(np.diff(states[:, POSITION], axis=0), axis=1)
    assert jumps.max() < 0.2  # m per frame: at most 5 m/s


def test_a_stuck_thruster_that_spins_the_body_up_ends_the_episode_tumbling():
    env = dynamic_env()
    result = fly_episode(env, Coast(), seed=0, scenario=stuck_on())
    limit = DynamicConfig.max_body_rate
    w = rates(result.states)
    assert result.outcome == S.TUMBLING
    # It ends at the first frame past the limit, which is the episode's last.
    first_past = int(np.argmax(w > limit))
    assert w[first_past] > limit and (w[:first_past] <= limit).all()
    assert result.length == first_past + 1 and ONSET < first_past < 60
    assert result.actions[-1].tolist() == [0.0] * S.ACTION_DIM  # the terminal frame, as any
    assert_never_reset(env, result.states)
    with pytest.raises(RuntimeError, match="has ended"):
        env.step(np.zeros(S.ACTION_DIM))


def test_the_exploratory_pilot_with_a_dead_thruster_tumbles_instead_of_flying_on_from_a_reset():
    # Seed 200 of the dynamic tier: thruster 6 off from t = 0. Before the rate limit existed the
    # exploratory pilot spun the body up until MuJoCo reset the state (frame 216) and the
    # episode went on from there to a timeout.
    seed = 200
    scn = sample_scenario(seed, ScenarioConfig.for_tier("dynamic"))
    assert (scn.dynamics.fault.kind, scn.dynamics.fault.onset_step) == ("off", 0)
    env = dynamic_env()
    result = fly_episode(env, make_pilot("exploratory"), seed)
    assert result.outcome == S.TUMBLING
    assert rates(result.states)[-1] > DynamicConfig.max_body_rate
    assert_never_reset(env, result.states)


def test_without_the_limit_the_env_raises_where_mujoco_resets_the_state(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs its warning to MUJOCO_LOG.TXT in the working directory
    env = dynamic_env(max_body_rate=1e12)
    env.reset(options={"scenario": stuck_on()})
    with pytest.raises(SimulationUnstable, match="reset it") as err:
        for _ in range(env.sim.max_steps):
            env.step(np.zeros(S.ACTION_DIM))
    assert env.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0  # MuJoCo did reset it
    assert f"frame {env.t}" in str(err.value) and "max_body_rate" in str(err.value)
    with pytest.raises(RuntimeError, match="has ended"):  # and the episode does not go on
        env.step(np.zeros(S.ACTION_DIM))


def test_the_static_tier_has_no_rate_limit(physics_env):
    """The static body (isotropic inertia: a spin has no gyroscopic term) spins past the dynamic
    tier's limit and flies on to one of the static tier's own outcomes."""
    physics_env.reset(seed=3, options={"n_obstacles": 0})
    spin = np.zeros(S.ACTION_DIM)
    spin[0] = 1.0  # one thruster full on: torque and force
    peak, info = 0.0, {"outcome": None}
    while info["outcome"] is None:
        _, _, _, _, info = physics_env.step(spin)
        peak = max(peak, physics_env.body_rate)
    assert peak > 10 * DynamicConfig.max_body_rate
    assert info["outcome"] in S.OUTCOMES and S.TUMBLING not in S.OUTCOMES
    for warning in INSTABILITY_WARNINGS:
        assert physics_env.data.warning[warning].number == 0


def test_the_limit_must_be_positive():
    with pytest.raises(ValueError, match="max_body_rate"):
        DynamicConfig(max_body_rate=0.0)
