"""``CubeSat-v1`` as a registered Gymnasium environment: conformance, its keywords, and parity
with the dataset (an expert episode replayed through the Gymnasium API gives the recorded frames)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pyarrow.parquet as pq
import pytest
from gymnasium.utils.env_checker import check_env

import orbitdata.sim.gym  # noqa: F401  (registers CubeSat-v1)
from orbitdata import read_meta
from orbitdata import schema as S
from orbitdata.config import GenerationConfig


def test_the_environment_passes_gymnasiums_checker():
    env = gym.make("CubeSat-v1", n_obstacles=3, speed=2.0, image_size=64)
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=5)
    assert set(obs) == {"image", "depth", "state", "goal"} and obs["image"].shape == (64, 64, 3)
    assert env.observation_space.contains(obs) and info["outcome"] is None and info["episode_seed"] == 5
    assert len(env.unwrapped.env.scenario.obstacles) == 3
    assert np.isclose(np.linalg.norm(env.unwrapped.env.scenario.initial_velocity), 2.0)
    env.close()


def test_make_keywords_and_the_module_form():
    env = gym.make("orbitdata.sim.gym:CubeSat-v1", images=False, seed=7)  # imports and registers
    first, info = env.reset()
    assert set(first) == {"state", "goal"} and info["episode_seed"] == 7  # seed: the first reset's
    _, again = env.reset()
    assert again["episode_seed"] != 7  # later resets draw from the env's seeded generator
    replay, info = env.reset(seed=7)
    assert np.array_equal(replay["state"], first["state"]) and np.array_equal(replay["goal"], first["goal"])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        env.step(np.full(8, 2.0, np.float32))
    env.close()


def test_an_expert_episode_replayed_through_gymnasium_gives_the_dataset_frames(tiny_dataset_master):
    """Same world from the episode's seed, same recorded thrusts -> the recorded states, bit for bit,
    and the recorded outcome (the images are stored as JPEG, so the states are what is compared)."""
    info, _ = read_meta(tiny_dataset_master)
    config = GenerationConfig.from_dict(info.config)
    episodes = pq.read_table(tiny_dataset_master / "episodes" / "train-00000-of-00001.parquet").to_pylist()
    episode = next(e for e in episodes if e[S.LEVEL] == "expert")
    steps = pq.read_table(tiny_dataset_master / episode["data_file"]).to_pandas()
    rows = steps[steps[S.EPISODE_INDEX] == episode[S.EPISODE_INDEX]].sort_values(S.FRAME_INDEX)
    states = np.stack(rows[S.STATE].to_numpy())  # (L, 16)
    actions = np.stack(rows[S.ACTION].to_numpy())  # (L, 8), the last row the terminal frame's zeros

    env = gym.make("CubeSat-v1", sim=config.sim, scenario=config.scenario)
    obs, info = env.reset(seed=episode[S.SEED])
    got, outcome = [obs["state"]], None
    for action in actions[:-1]:
        obs, reward, terminated, truncated, info = env.step(action)
        got.append(obs["state"])
        if terminated or truncated:
            outcome = info["outcome"]
            break
    env.close()
    assert len(got) == len(states) == episode[S.LENGTH]
    assert np.array_equal(np.stack(got), states)  # bit for bit
    assert outcome == episode[S.OUTCOME]


def test_without_the_extra_the_import_says_how_to_install_it(monkeypatch):
    import importlib
    import sys

    monkeypatch.delitem(sys.modules, "orbitdata.sim.gym")
    monkeypatch.setitem(sys.modules, "gymnasium", None)
    with pytest.raises(ImportError, match=r"pip install 'orbitdata\[gym\]'"):
        importlib.import_module("orbitdata.sim.gym")
