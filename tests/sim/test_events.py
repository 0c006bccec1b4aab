"""Collisions, success and the step limit."""

import numpy as np
from scenes import free_space, wall_ahead

from orbitdata.sim import CubeSatEnv, SimConfig


def test_forced_collision_is_detected_on_the_contact_step(physics_env):
    obs, info = physics_env.reset(options={"scenario": wall_ahead(distance=1.0)})
    assert info["min_clearance"] > 0.9
    outcome, steps = None, 0
    while outcome is None:
        obs, reward, terminated, truncated, info = physics_env.step(np.zeros(8))
        steps += 1
        outcome = info["outcome"]
    assert outcome == "collision" and terminated and reward == -1.0
    # 1 m at 2 m/s: contact during the 13th step (0.48 s < t <= 0.52 s).
    assert steps == 13
    assert info["min_clearance"] == 0.0
    assert info["contact_substep"] is not None


def test_no_collision_in_free_flight(physics_env):
    physics_env.reset(options={"scenario": free_space(velocity=(2.0, 0.5, 0.0))})
    for _ in range(100):
        _, _, terminated, _, info = physics_env.step(np.full(8, 0.05))
        assert not info["collision"] and not terminated


def test_success_on_entering_the_goal(physics_env):
    physics_env.reset(options={"scenario": free_space(velocity=(2.0, 0.0, 0.0), goal=(1.0, 0.0, 0.0))})
    outcome = None
    for _ in range(30):
        _, reward, terminated, _, info = physics_env.step(np.zeros(8))
        if terminated:
            outcome = info["outcome"]
            break
    assert outcome == "success" and reward == 1.0


def test_step_limit_truncates():
    env = CubeSatEnv(SimConfig(render=False, max_steps=20))
    env.reset(options={"scenario": free_space()})
    for t in range(1, 20):
        _, _, terminated, truncated, info = env.step(np.zeros(8))
        if truncated:
            break
    assert truncated and not terminated and info["outcome"] == "timeout" and t == 19
    try:
        env.step(np.zeros(8))
    except RuntimeError as exc:
        assert "reset" in str(exc)
    else:
        raise AssertionError("stepping a finished episode must fail")
