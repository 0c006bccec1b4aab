"""Thrust noise on any pilot (the Diffusion Policy's sanity ladder): seeded per episode, redrawn
every step or held for a chunk of steps, clipped to the thrust box."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from orbitdata.cli.app import app
from orbitdata.fly import Pilot, Task
from orbitdata.fly.noise import ThrustNoise


class Constant(Pilot):
    name = "constant"

    def reset(self, task):
        self.resets = getattr(self, "resets", 0) + 1

    def act(self, obs):
        return np.full(8, 0.5)

    def metadata(self):
        return {"inner": True}


def noise_of(pilot: ThrustNoise, seed: int, steps: int) -> np.ndarray:
    pilot.reset(Task((1.0, 0.0, 0.0), 0.5, (0.0, 0.0, 0.0), seed))
    return np.stack([pilot.act({}) for _ in range(steps)]) - 0.5


def test_noise_is_redrawn_every_hold_steps_and_seeded_by_the_episode():
    held = noise_of(ThrustNoise(Constant(), 0.05, hold=4), seed=3, steps=8)
    assert np.array_equal(held[0], held[3]) and not np.array_equal(held[3], held[4])
    assert np.array_equal(held, noise_of(ThrustNoise(Constant(), 0.05, hold=4), seed=3, steps=8))
    assert not np.array_equal(held, noise_of(ThrustNoise(Constant(), 0.05, hold=4), seed=4, steps=8))
    step = noise_of(ThrustNoise(Constant(), 0.05), seed=3, steps=8)
    assert all(not np.array_equal(step[k], step[k + 1]) for k in range(7))
    assert 0.02 < step.std() < 0.08 and not noise_of(ThrustNoise(Constant(), 0.0), 3, 4).any()
    big = noise_of(ThrustNoise(Constant(), 5.0), seed=3, steps=8) + 0.5
    assert big.min() >= 0.0 and big.max() <= 1.0  # clipped to the thrust box
    assert ThrustNoise(Constant(), 0.05, 8).metadata() == {"inner": True, "thrust_noise": 0.05, "noise_hold": 8}
    with pytest.raises(ValueError, match="hold"):
        ThrustNoise(Constant(), 0.05, hold=0)


def test_orbitdata_fly_flies_the_noisy_expert(tmp_path):
    out = tmp_path / "noisy.json"
    res = CliRunner().invoke(
        app,
        [
            "fly",
            "--pilot",
            "expert",
            "--obstacles",
            "1",
            "--speeds",
            "1",
            "--episodes",
            "1",
            "--thrust-noise",
            "0.05",
            "--noise-hold",
            "8",
            "--json",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    assert report["pilot"] == "expert+noise0.05x8" and report["settings"][0]["episodes"] == 1
    assert report["flight"] == {"pilot_options": {}, "image_codec": False, "thrust_noise": 0.05, "noise_hold": 8}
