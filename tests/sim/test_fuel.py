"""Fuel depletes with thrust, mass and inertia follow it, and thrust stops at an empty tank."""

import dataclasses

import numpy as np
import pytest
from scenes import free_space, pure_force_thrust

from orbitdata.sim import CubeSatConfig, CubeSatEnv, SimConfig
from orbitdata.sim.config import G0


def test_fuel_is_monotone_and_matches_mass_flow(physics_env):
    obs, _ = physics_env.reset(options={"scenario": free_space()})
    rng = np.random.default_rng(1)
    fuel, masses = [obs["state"][15]], [physics_env.mass]
    total_thrust = 0.0
    for _ in range(40):
        u = rng.uniform(0, 1, 8) * (rng.uniform() < 0.7)
        total_thrust += u.sum()
        obs, *_ = physics_env.step(u)
        fuel.append(obs["state"][15])
        masses.append(physics_env.mass)
    assert np.all(np.diff(fuel) <= 0) and fuel[-1] < fuel[0]
    sat = physics_env.sim.cubesat
    burned = total_thrust * sat.max_thrust / (sat.isp * G0) * physics_env.sim.dt
    assert np.isclose((fuel[0] - fuel[-1]) * sat.fuel_mass, burned, rtol=1e-5)
    np.testing.assert_allclose(masses, sat.dry_mass + np.array(fuel, dtype=np.float64) * sat.fuel_mass, rtol=1e-6)


def test_lighter_craft_accelerates_more(physics_env):
    obs, _ = physics_env.reset(options={"scenario": free_space(goal=(-1000.0, 0.0, 0.0))})
    u = pure_force_thrust(physics_env, [6.0, 0.0, 0.0])
    m_full = physics_env.mass
    v_before = obs["state"][3]
    obs, *_ = physics_env.step(u)
    dv_full = obs["state"][3] - v_before
    for _ in range(200):  # burn a good part of the tank
        obs, *_ = physics_env.step(u)
    m_light = physics_env.mass
    v_before = obs["state"][3]
    obs, *_ = physics_env.step(u)
    dv_light = obs["state"][3] - v_before
    assert m_light < 0.9 * m_full
    # Same force, dv = F dt / m: the velocity gain scales with the inverse mass.
    assert dv_light / dv_full == pytest.approx(m_full / m_light, rel=2e-3)


def test_empty_tank_stops_thrust_and_ends_episode():
    sat = dataclasses.replace(CubeSatConfig(), fuel_mass=0.01)
    env = CubeSatEnv(SimConfig(cubesat=sat, render=False))
    obs, _ = env.reset(options={"scenario": free_space()})
    u = pure_force_thrust(env, [6.0, 0.0, 0.0])
    outcome = None
    for _ in range(50):
        obs, _, terminated, _, info = env.step(u)
        if terminated:
            outcome = info["outcome"]
            break
    assert outcome == "out_of_fuel"
    assert obs["state"][15] == 0.0
    assert info["thrust"].sum() < u.sum()  # the last step was scaled to what was left
