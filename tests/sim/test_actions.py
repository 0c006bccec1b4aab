"""Bad actions and bad reset calls get clear errors."""

import numpy as np
import pytest

from orbitdata.scenario.sampler import ImpossibleScenario
from orbitdata.scenario.spec import Obstacle, Scenario


@pytest.mark.parametrize(
    "action, message",
    [
        (np.full(8, np.nan), "NaN or Inf"),
        (np.r_[np.zeros(7), np.inf], "NaN or Inf"),
        (np.zeros(7), r"shape \(8,\)"),
        (np.zeros((2, 8)), r"shape \(8,\)"),
        (np.r_[np.zeros(7), 1.5], r"\[0, 1\]"),
        (np.r_[np.zeros(7), -0.1], r"\[0, 1\]"),
    ],
)
def test_bad_actions_are_rejected(physics_env, action, message):
    physics_env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        physics_env.step(action)


def test_reset_requires_a_seed_or_scenario(physics_env):
    with pytest.raises(ValueError, match="seed"):
        physics_env.reset()
    with pytest.raises(ValueError, match="unknown reset options"):
        physics_env.reset(seed=0, options={"speeed": 1})


def test_impossible_scenarios_are_rejected(physics_env):
    blocked_goal = Scenario(obstacles=(Obstacle("sphere", (5.0, 0, 0), (1.0, 0, 0)),), goal=(5.0, 0.0, 0.0))
    with pytest.raises(ImpossibleScenario, match="goal"):
        physics_env.reset(options={"scenario": blocked_goal})
    overlapping_start = Scenario(obstacles=(Obstacle("box", (0.1, 0, 0), (0.2, 0.2, 0.2)),), goal=(5.0, 0, 0))
    with pytest.raises(ImpossibleScenario, match="start"):
        physics_env.reset(options={"scenario": overlapping_start})
