"""``CubeSat-v1`` as a registered Gymnasium environment: conformance, its keywords (checked at
``make``), async vector envs, and parity with the dataset (an expert episode replayed through the
Gymnasium API gives the recorded frames under the dataset's column names)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pyarrow.parquet as pq
import pytest
from gymnasium.utils.env_checker import check_env

import orbitdata
import orbitdata.sim.gym  # noqa: F401  (registers CubeSat-v1)
from orbitdata import read_meta
from orbitdata import schema as S
from orbitdata.codecs import decode_depth, decode_rgb, depth_to_mm, encode_rgb
from orbitdata.config import GenerationConfig
from orbitdata.scenario import ScenarioConfig

IMAGE_KEYS = {S.IMAGE, S.DEPTH, S.DEPTH_LOW}


def test_the_environment_passes_gymnasiums_checker():
    env = gym.make("CubeSat-v1", n_obstacles=3, speed=2.0, image_size=64)
    check_env(env.unwrapped)  # the render check too: rgb_array
    obs, info = env.reset(seed=5)
    assert set(obs) == {S.STATE, S.GOAL} | IMAGE_KEYS and obs[S.IMAGE].shape == (64, 64, 3)
    assert obs[S.DEPTH_LOW].shape == (S.DEPTH_LOW_SIDE, S.DEPTH_LOW_SIDE) and obs[S.DEPTH_LOW].dtype == np.float32
    assert env.observation_space.contains(obs) and info["outcome"] is None and info["episode_seed"] == 5
    assert len(env.unwrapped.env.scenario.obstacles) == 3
    assert np.isclose(np.linalg.norm(env.unwrapped.env.scenario.initial_velocity), 2.0)
    env.close()


def test_without_images_the_checker_passes_and_nothing_renders():
    env = gym.make("CubeSat-v1", images=False)
    assert env.metadata["render_modes"] == []
    check_env(env.unwrapped)  # no render check left to fail on
    with pytest.raises(ValueError, match="render_mode='rgb_array'"):
        gym.make("CubeSat-v1", images=False, render_mode="rgb_array")
    env.close()


def test_make_keywords_and_the_module_form():
    env = gym.make("orbitdata.sim.gym:CubeSat-v1", images=False, seed=7)  # imports and registers
    first, info = env.reset()
    assert set(first) == {S.STATE, S.GOAL} and info["episode_seed"] == 7  # seed: the first reset's
    _, again = env.reset()
    assert again["episode_seed"] != 7  # later resets draw from the env's seeded generator
    replay, info = env.reset(seed=7)
    assert np.array_equal(replay[S.STATE], first[S.STATE]) and np.array_equal(replay[S.GOAL], first[S.GOAL])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        env.step(np.full(8, 2.0, np.float32))
    env.close()


def test_a_given_scenario_flies_and_reports_the_seed_that_drew_it():
    env = gym.make("CubeSat-v1", images=False)
    env.reset(seed=3)
    scenario = env.unwrapped.env.scenario
    first = env.unwrapped.env.data.qpos.copy()
    _, info = env.reset(options={"scenario": scenario})
    assert info["episode_seed"] == scenario.seed == 3  # reset(seed=3) flies it again, as the info promises
    assert np.array_equal(env.unwrapped.env.data.qpos, first)
    for options, message in (
        ({"scenario": scenario, "n_obstacles": 5}, r"options \['n_obstacles'\] beside options\['scenario'\]"),
        ({"scenario": ScenarioConfig()}, "is a ScenarioConfig: give an episode's Scenario"),
    ):
        with pytest.raises(ValueError, match=message):
            env.reset(options=options)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"n_obstacles": 2.5}, "n_obstacles=2.5"),
        ({"n_obstacles": -1}, "n_obstacles=-1"),
        ({"n_obstacles": 10**20}, "n_obstacles=100000000000000000000: give a whole number of obstacles from 0 to 1000"),
        ({"speed": -1.0}, "speed=-1.0"),
        ({"speed": float("nan")}, "speed=nan"),
        ({"max_steps": 0}, "max_steps=0"),
        ({"max_steps": 2.0}, "max_steps=2.0"),
        ({"image_size": 100}, "image_size must be a multiple of 16"),
        ({"seed": -3}, "seed=-3"),
        ({"images": "no"}, "images='no'"),
    ],
)
def test_bad_arguments_are_refused_at_make_naming_them(kwargs, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[")):
        gym.make("CubeSat-v1", **{"images": False, **kwargs})


def test_the_dynamic_tier_passes_the_checker_and_observes_what_the_static_tier_does():
    env = gym.make("CubeSat-v1", tier="dynamic", image_size=64)
    check_env(env.unwrapped)  # reset with a seed twice gives the same noisy frames, as it must
    obs, info = env.reset(seed=2)
    scenario = env.unwrapped.env.scenario
    assert scenario.tier == "dynamic" and scenario.dynamics is not None
    assert set(obs) == {S.STATE, S.GOAL} | IMAGE_KEYS  # no obstacle pose: that is privileged, in info
    assert info["obstacle_poses"].shape == (len(scenario.obstacles), 7)
    assert env.observation_space == gym.make("CubeSat-v1", image_size=64).observation_space
    env.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"tier": "moving"}, "tier='moving': give one of 'static', 'dynamic'"),
        ({"tier": "dynamic", "scenario": ScenarioConfig()}, "tier='dynamic' but scenario.tier is 'static'"),
    ],
)
def test_a_bad_tier_is_refused_at_make(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("CubeSat-v1", images=False, **kwargs)


@pytest.mark.parametrize("max_steps", [1, 5])
def test_max_steps_is_the_number_of_steps(max_steps):
    env = gym.make("CubeSat-v1", images=False, n_obstacles=0, speed=0.0, max_steps=max_steps)
    env.reset(seed=1)
    steps, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, info = env.step(np.zeros(8, np.float32))
        steps += 1
        assert not terminated
    assert steps == max_steps and info["outcome"] == "timeout"
    env.close()


def test_by_default_an_episode_is_as_long_as_the_datasets():
    env = gym.make("CubeSat-v1", images=False, n_obstacles=0, speed=0.0)
    env.reset(seed=1)
    steps = 1
    while not env.step(np.zeros(8, np.float32))[3]:
        steps += 1
    assert steps + 1 == GenerationConfig().sim.max_steps  # 299 steps, 300 frames
    env.close()


ASYNC = """
import json, sys
import gymnasium as gym, numpy as np
import orbitdata.sim.gym
from orbitdata import schema as S

kw = dict(image_size=32, n_obstacles=1, speed=1.0)
env = gym.make("CubeSat-v1", **kw)
first, _ = env.reset(seed=3)  # this process renders before it forks the workers
vec = gym.make_vec("CubeSat-v1", num_envs=2, vectorization_mode="async", **kw)
obs, _ = vec.reset(seed=[3, 4])
stepped = vec.step(np.zeros((2, 8), np.float32))[0]
vec.close()
again, _ = env.reset(seed=3)  # and renders again after the fork
env.close()
print(json.dumps({"worker": bool(np.array_equal(obs[S.IMAGE][0], first[S.IMAGE])),
                  "parent": bool(np.array_equal(again[S.IMAGE], first[S.IMAGE])),
                  "stepped": list(stepped[S.IMAGE].shape)}))
"""


def test_an_async_vector_env_runs_in_a_process_that_has_rendered():
    """A forked worker used to wait forever in the renderer (and outlive a killed parent): the
    script runs in its own process group, killed whole if it does not finish."""
    paths = [str(Path(orbitdata.__file__).parents[1]), os.environ.get("PYTHONPATH", "")]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in paths if p))
    proc = subprocess.Popen(
        [sys.executable, "-c", ASYNC],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=240)  # seconds normally; a guard against a hang
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the script and its workers
        proc.communicate()
        pytest.fail("the async vector env hung in reset")
    assert proc.returncode == 0, err
    result = json.loads(out.strip().splitlines()[-1])
    assert result == {"worker": True, "parent": True, "stepped": [2, 32, 32, 3]}


def _recorded_expert_episode(dataset: Path):
    info, _ = read_meta(dataset)
    episodes = pq.read_table(dataset / "episodes" / "train-00000-of-00001.parquet").to_pylist()
    episode = next(e for e in episodes if e[S.LEVEL] == "expert")
    steps = pq.read_table(dataset / episode["data_file"]).to_pandas()
    rows = steps[steps[S.EPISODE_INDEX] == episode[S.EPISODE_INDEX]].sort_values(S.FRAME_INDEX)
    return GenerationConfig.from_dict(info.config), episode, rows


def test_an_expert_episode_replayed_through_gymnasium_gives_the_dataset_frames(tiny_dataset_master):
    """Same world from the episode's seed, same recorded thrusts -> the recorded rows under the
    same names: states and depth_low bit for bit, the image and depth as the dataset encodes them
    (JPEG at the dataset's quality, whole millimetres), and the recorded outcome."""
    config, episode, rows = _recorded_expert_episode(tiny_dataset_master)
    actions = np.stack(rows[S.ACTION].to_numpy())  # (L, 8), the last row the terminal frame's zeros

    env = gym.make("CubeSat-v1", sim=config.sim, scenario=config.scenario)
    obs, info = env.reset(seed=episode[S.SEED])
    got, outcome = [obs], None
    for action in actions[:-1]:
        obs, reward, terminated, truncated, info = env.step(action)
        got.append(obs)
        if terminated or truncated:
            outcome = info["outcome"]
            break
    env.close()
    assert len(got) == len(rows) == episode[S.LENGTH] and outcome == episode[S.OUTCOME]
    assert np.array_equal(got[0][S.GOAL], np.asarray(episode[S.GOAL], np.float32))
    for obs, (_, row) in zip(got, rows.iterrows()):
        image, depth = decode_rgb(row[S.IMAGE]["bytes"]), decode_depth(row[S.DEPTH]["bytes"])
        assert np.array_equal(obs[S.STATE], np.asarray(row[S.STATE], np.float32))  # bit for bit
        assert np.array_equal(obs[S.DEPTH_LOW], np.asarray(row[S.DEPTH_LOW], np.float32).reshape(16, 16))
        assert encode_rgb(obs[S.IMAGE], config.dataset.jpeg_quality) == row[S.IMAGE]["bytes"]
        assert np.array_equal(depth_to_mm(obs[S.DEPTH]).astype(np.float32) / 1000, depth)
        for key, decoded in ((S.IMAGE, image), (S.DEPTH, depth)):  # what a row decodes to
            assert (obs[key].shape, obs[key].dtype) == (decoded.shape, decoded.dtype)


def test_without_the_extra_the_import_says_how_to_install_it(monkeypatch):
    import importlib
    import sys

    monkeypatch.delitem(sys.modules, "orbitdata.sim.gym")
    monkeypatch.setitem(sys.modules, "gymnasium", None)
    with pytest.raises(ImportError, match=r"pip install 'orbitdata\[gym\]'"):
        importlib.import_module("orbitdata.sim.gym")
