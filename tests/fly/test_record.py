"""A grid episode's record: the delta-v is what the thrusters gave, and `orbitdata fly --json`
keeps one record per episode, as `orbitmodel eval closed-loop` does."""

import json

import numpy as np
import pytest
from scenes import free_space
from typer.testing import CliRunner

from orbitdata.cli.app import app
from orbitdata.fly.record import delta_v
from orbitdata.sim import CubeSatConfig, CubeSatEnv, SimConfig


def test_delta_v_is_the_thrust_over_the_mass_summed_over_the_flight():
    env = CubeSatEnv(SimConfig(render=False))
    obs, _ = env.reset(options={"scenario": free_space()})
    rng = np.random.default_rng(3)
    fuel0, given = float(obs["state"][15]), 0.0
    sat, dt = env.sim.cubesat, env.sim.dt
    for _ in range(60):
        u = rng.uniform(0, 1, 8)
        mass = env.mass
        obs, *_ = env.step(u)
        # the step's thrust over the mass halfway through it: every thruster's, cancelling or not
        given += u.sum() * sat.max_thrust / (0.5 * (mass + env.mass)) * dt
    env.close()
    assert delta_v(sat, fuel0, float(obs["state"][15])) == pytest.approx(given, rel=1e-6)


def test_a_heavier_body_gets_less_delta_v_from_the_same_fuel():
    sat = CubeSatConfig()
    assert delta_v(sat, 1.0, 1.0) == 0.0
    light, heavy = delta_v(sat, 1.0, 0.5, mass_scale=0.8), delta_v(sat, 1.0, 0.5, mass_scale=1.2)
    assert light > delta_v(sat, 1.0, 0.5) > heavy > 0


def test_fly_json_keeps_every_episodes_record(tmp_path):
    out = tmp_path / "grid.json"
    args = ["fly", "--tier", "dynamic", "--pilot", "expert", "--obstacles", "3", "--speeds", "1", "--episodes", "2"]
    res = CliRunner().invoke(app, [*args, "--seed", "7", "--json", str(out)])
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    episodes = report["episodes"]
    assert [e["episode"] for e in episodes] == [0, 1] and len({e["seed"] for e in episodes}) == 2
    assert [e["outcome"] for e in episodes].count("success") == report["settings"][0]["success"]
    for e in episodes:
        assert e["frames"] > 1 and e["min_clearance_m"] >= 0 and e["debris"] == 3
        assert e["fuel_used"] > 0 and e["delta_v_mps"] > 0
        assert e["fault"] in ("none", "off", "scaled", "stuck") and isinstance(e["eclipse"], bool)
