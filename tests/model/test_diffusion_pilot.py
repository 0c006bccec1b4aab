"""The Diffusion Policy as a pilot: the interface, action chunking, seeding, and that it is
told only the task (never the obstacles) and reads only the camera image and the state."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pytest
import torch

from orbitdata.fly import Task
from orbitmodel.baselines.diffusion.config import get_policy_preset
from orbitmodel.baselines.diffusion.pilot import DiffusionPilot, load_policy_pilot, make_diffusion_pilot
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy
from orbitmodel.baselines.diffusion.sampling import PolicySampling
from orbitmodel.baselines.diffusion.train import policy_run_config
from orbitmodel.data import DatasetMeta
from orbitmodel.runs import RunDir

torch.set_num_threads(1)
PRESET = get_policy_preset("tiny")


class SpyTask(Task):
    """Records every attribute the pilot reads."""

    read: set

    def __getattribute__(self, name):
        if not name.startswith("__") and name != "read":
            object.__getattribute__(self, "read").add(name)
        return object.__getattribute__(self, name)


def spy_task(goal, seed) -> SpyTask:
    task = SpyTask(goal=tuple(goal), goal_radius=0.5, initial_velocity=(0.0, 0.0, 0.0), seed=seed)
    object.__setattr__(task, "read", set())
    return task


class SpyObs(dict):
    """An observation dict that records the keys the pilot reads."""

    def __init__(self, *args):
        super().__init__(*args)
        self.read = set()

    def __getitem__(self, key):
        self.read.add(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        self.read.add(key)
        return super().get(key, default)


@pytest.fixture(scope="module")
def policy() -> DiffusionPolicy:
    torch.manual_seed(0)
    return DiffusionPolicy(PRESET.model).eval()  # untrained: the interface does not care


@pytest.fixture(scope="module")
def env():
    from orbitdata.sim import CubeSatEnv
    from orbitdata.sim.config import CameraConfig, SimConfig

    e = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=64)))
    yield e
    e.close()


def test_interface():
    assert DiffusionPilot.name == "diffusion"
    assert DiffusionPilot.privileged is False
    assert DiffusionPilot.needs_images is True
    assert list(inspect.signature(DiffusionPilot.reset).parameters) == ["self", "task"]  # no scenario


def test_flies_with_chunks_and_never_sees_the_obstacles(policy, env, monkeypatch):
    pilot = DiffusionPilot(policy)
    calls = []
    sample = policy.sample_actions
    monkeypatch.setattr(policy, "sample_actions", lambda *a, **k: calls.append(a[0].shape) or sample(*a, **k))
    obs, info = env.reset(seed=7, options={"n_obstacles": 3, "speed": 1.0})
    task = spy_task(env.scenario.goal, seed=7)
    pilot.reset(task)
    read = set()
    for t in range(17):
        o = SpyObs(obs)
        action = pilot.act(o)
        read |= o.read
        assert action.shape == (8,) and action.dtype == np.float32
        assert action.min() >= 0 and action.max() <= 1
        obs, _, _, _, info = env.step(action.astype(np.float64))
        assert info["outcome"] is None
    assert task.read <= {"goal", "seed"}  # told the goal only, never the obstacles
    assert read == {"image", "state"}  # no depth
    assert len(calls) == 3  # a new chunk at steps 0, 8 and 16
    assert calls[0] == (1, 2, 3, 64, 64)


def test_a_policy_without_images_flies_without_a_camera():
    """The state + goal variant (``PolicyConfig.images`` False): the env need not render, the pilot
    reads the state only, and its actions do not depend on any image."""
    from dataclasses import replace

    from orbitdata.sim import CubeSatEnv
    from orbitdata.sim.config import SimConfig

    torch.manual_seed(0)
    blind = DiffusionPolicy(replace(PRESET.model, images=False)).eval()
    assert blind.net.obs_encoder.image is None
    pilot = DiffusionPilot(blind)
    assert pilot.needs_images is False
    env = CubeSatEnv(SimConfig(render=False))
    try:
        obs, _ = env.reset(seed=3, options={"n_obstacles": 1, "speed": 1.0})
        assert "image" not in obs
        pilot.reset(Task(tuple(env.scenario.goal), 0.5, (0.0, 0.0, 0.0), 3))
        read = set()
        for _ in range(9):
            o = SpyObs({**obs, "image": np.zeros((64, 64, 3), np.uint8)})  # a camera it must not look at
            action = pilot.act(o)
            read |= o.read
            obs, *_ = env.step(action.astype(np.float64))
    finally:
        env.close()
    assert read == {"state"}
    states, goal = torch.zeros(2, 2, 16), torch.tensor([[2.0, 0.0, 0.0]] * 2)
    states[..., 6] = states[..., 9] = 1.0  # identity rotation
    images = torch.randint(0, 256, (2, 2, 3, 64, 64), dtype=torch.uint8)
    draw = [blind.sample_actions(x, states, goal, torch.Generator().manual_seed(0)) for x in (None, images)]
    torch.testing.assert_close(draw[0], draw[1], rtol=0, atol=0)
    with pytest.raises(ValueError, match="pass its images"):
        DiffusionPolicy(PRESET.model).sample_actions(None, states, goal)


def test_an_episode_is_reproducible_from_its_seed(policy):
    rng = np.random.default_rng(0)
    obs = {"image": rng.integers(0, 256, (64, 64, 3), dtype=np.uint8), "state": np.zeros(16, np.float32)}
    obs["state"][6:12] = [1, 0, 0, 1, 0, 0]

    def first_actions(seed):
        pilot = DiffusionPilot(policy)
        pilot.reset(Task((2.0, 0.0, 0.0), 0.5, (0.0, 0.0, 0.0), seed))
        return np.stack([pilot.act(obs) for _ in range(3)])

    np.testing.assert_array_equal(first_actions(1), first_actions(1))
    assert not np.array_equal(first_actions(1), first_actions(2))


def test_noise_scale_gathers_the_draws(policy):
    """sample_actions' noise_scale scales the noise DDIM starts from: at 0 every draw is the same
    chunk whatever the generator, and a smaller scale spreads the draws less."""
    states = torch.zeros(64, 2, 16)
    states[..., 6] = states[..., 9] = 1.0
    images = torch.randint(0, 256, (1, 2, 3, 64, 64), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))
    images, goal = images.expand(64, -1, -1, -1, -1), torch.tensor([[2.0, 1.0, 0.0]]).expand(64, -1)

    def draws(scale, seed):
        return policy.sample_actions(
            images, states, goal, torch.Generator().manual_seed(seed), sampling=PolicySampling(noise_scale=scale)
        )

    zero = draws(0.0, 1)
    torch.testing.assert_close(zero, draws(0.0, 2), rtol=0, atol=0)
    torch.testing.assert_close(zero, zero[:1].expand_as(zero), rtol=0, atol=0)  # 64 draws, one chunk
    spread = {s: draws(s, 1).var(0).mean().item() for s in (0.3, 1.0)}
    assert 0 < spread[0.3] < spread[1.0]
    with pytest.raises(ValueError, match="noise_scale=-0.5"):
        draws(-0.5, 1)


def test_errors(policy):
    pilot = DiffusionPilot(policy)
    obs = {"image": np.zeros((32, 32, 3), np.uint8), "state": np.zeros(16, np.float32)}
    with pytest.raises(RuntimeError, match="reset"):
        pilot.act(obs)
    pilot.reset(Task((1.0, 0.0, 0.0), 0.5, (0.0, 0.0, 0.0), 0))
    with pytest.raises(ValueError, match="64 px"):
        pilot.act(obs)
    with pytest.raises(ValueError, match="run="):
        make_diffusion_pilot(None)


def save_policy_run(policy, path, preset=PRESET) -> RunDir:
    """``policy`` (of ``preset``) as a policy run folder of a 64 px dataset (root seed 0, one episode)."""
    meta = DatasetMeta(
        source="x",
        image_size=64,
        state_mean=(0.0,) * 16,
        state_std=(1.0,) * 16,
        action_mean=(0.1,) * 8,
        action_std=(0.1,) * 8,
        depth_max=50.1,
        fovy_deg=100.0,
        root_seed=0,
        episodes={"train": 1},
    )
    run = RunDir(path)
    run.start(policy_run_config(preset, meta, ["expert"], []), resume=False, overwrite=False)
    run.save_final(policy.state_dict(), step=0)
    return run


def test_loads_from_a_run_folder(policy, tmp_path):
    run = save_policy_run(policy, tmp_path / "run")
    pilot = load_policy_pilot(run.path)
    for k, v in policy.state_dict().items():
        assert torch.equal(pilot.policy.state_dict()[k], v), k
    from orbitdata.config import GenerationConfig

    config = GenerationConfig()  # renders 224 px by default
    with pytest.raises(ValueError, match="--image-size 64"):
        make_diffusion_pilot(config, run=str(run.path))
    # --pilot-option values arrive as text; without a flight preset the pilot flies the reported one (cpu)
    assert make_diffusion_pilot(None, run=str(run.path), noise_scale="0.5", draws="2").metadata()["noise_scale"] == 0.5
    assert make_diffusion_pilot(None, run=str(run.path), draws="3", pick="central").metadata()["pick"] == "central"
    flown = make_diffusion_pilot(None, run=str(run.path))
    assert flown.metadata() == {
        "preset": "cpu",
        "action_steps": 8,
        "ensemble": None,
        "draws": 1,
        "pick": "mean",
        "noise_scale": 1.0,
        "timestep_spacing": "trailing",
        "inference_steps": PRESET.model.inference_steps,
        "image_codec": True,
    }
    assert flown.image_codec and int(flown.policy.sampler_for(flown.sampling).timesteps[0]) == 99
    reference = make_diffusion_pilot(None, run=str(run.path), preset="reference")
    assert reference.metadata()["timestep_spacing"] == "leading" and reference.metadata()["preset"] == "reference"
    with pytest.raises(ValueError, match="timestep_spacing"):
        make_diffusion_pilot(None, run=str(run.path), timestep_spacing="middle")
    with pytest.raises(ValueError, match="noise_scale=cold"):
        make_diffusion_pilot(None, run=str(run.path), noise_scale="cold")
    with pytest.raises(ValueError, match="unknown policy flight preset 'fast'"):
        make_diffusion_pilot(None, run=str(run.path), preset="fast")
    with pytest.raises(ValueError, match="unknown policy setting 'samples'"):
        make_diffusion_pilot(None, run=str(run.path), samples="8")


def test_orbitdata_fly_hands_a_policy_its_camera_through_the_codec(policy, tmp_path):
    """`orbitdata fly --pilot diffusion` flies the flight preset's codec without --image-codec
    (the cpu preset sees the camera as the dataset stored it); `reference --set`-style options
    that turn it off fly raw renders."""
    from typer.testing import CliRunner

    from orbitdata.cli.app import app as orbitdata_app

    run = save_policy_run(policy, tmp_path / "run")
    grid = ["--obstacles", "1", "--speeds", "1", "--episodes", "1", "--image-size", "64", "--config"]
    toml = tmp_path / "short.toml"
    toml.write_text("[sim]\nmax_steps = 4\n")
    for options, codec in (([], True), (["--pilot-option", "image_codec=false"], False)):
        out = tmp_path / f"fly-{codec}.json"
        res = CliRunner().invoke(
            orbitdata_app,
            [
                "fly",
                "--pilot",
                "diffusion",
                "--pilot-option",
                f"run={run.path}",
                *options,
                *grid,
                str(toml),
                "--json",
                str(out),
            ],
        )
        assert res.exit_code == 0, res.output
        assert json.loads(out.read_text())["flight"]["image_codec"] is codec


def test_sampling_never_changes_the_policy(policy):
    """Flying a flight preset leaves the policy as it was: its config and its own sampler stay the
    run's, and a second pilot on the same policy samples its own way."""
    config, own = policy.config, policy.sampler.timesteps.tolist()
    trailing = DiffusionPilot(policy, PolicySampling(timestep_spacing="trailing"))
    leading = DiffusionPilot(policy, PolicySampling(timestep_spacing="leading"))
    assert policy.config == config and policy.sampler.timesteps.tolist() == own
    assert int(policy.sampler_for(trailing.sampling).timesteps[0]) == config.train_timesteps - 1
    assert policy.sampler_for(leading.sampling).timesteps.tolist() == own  # the tiny preset's run samples leading


def test_eval_closed_loop_flies_a_policy_run_as_itself(policy, tmp_path):
    """`orbitmodel eval closed-loop POLICY_RUN` flies the policy on the grid (it used to fail on
    reading the policy's config as a world model's), and refuses a planning --pilot for it."""
    from typer.testing import CliRunner

    from orbitmodel.cli.app import app

    run = save_policy_run(policy, tmp_path / "dp")
    out = tmp_path / "diffusion.json"
    grid = ["--obstacles", "1", "--speeds", "1", "--episodes", "1", "--max-steps", "4"]
    res = CliRunner().invoke(app, ["eval", "closed-loop", str(run.path), *grid, "--json", str(out)])
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    assert report["pilot"] == "diffusion" and report["planner"] is None and report["run"] == str(run.path)
    assert [e["frames"] for e in report["episodes"]] == [4]
    res = CliRunner().invoke(app, ["eval", "closed-loop", str(run.path), "--pilot", "oracle-true", *grid])
    assert res.exit_code == 2 and "flies as itself" in res.output and "Traceback" not in res.output
    assert report["preset"] == "cpu" and report["image_codec"] is True  # the reported flight by default
    assert report["pilot_settings"]["timestep_spacing"] == "trailing"
    res = CliRunner().invoke(app, ["eval", "closed-loop", str(run.path), "--set", "samples=8", *grid])
    assert res.exit_code == 2 and "unknown policy setting 'samples'" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(app, ["eval", "closed-loop", str(run.path), "--preset", "paper", *grid])
    assert res.exit_code == 2 and "flight presets are cpu, reference" in res.output
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "closed-loop",
            str(run.path),
            "--set",
            "action_steps=2",
            "--set",
            "ensemble=0.1",
            *grid,
            "--json",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    assert report["episodes"][0]["action_steps"] == 2
    assert report["pilot_settings"] == {
        "preset": "cpu",
        "action_steps": 2,
        "ensemble": 0.1,
        "draws": 1,
        "pick": "mean",
        "noise_scale": 1.0,
        "timestep_spacing": "trailing",
        "inference_steps": PRESET.model.inference_steps,
        "image_codec": True,
    }
    assert report["threads"] >= 1
    assert report["cpu_capability"] == torch.backends.cpu.get_cpu_capability()  # the kernels it flew on
    res = CliRunner().invoke(
        app,
        ["eval", "closed-loop", str(run.path), "--set", "draws=2", "--set", "pick=central", *grid, "--json", str(out)],
    )
    assert res.exit_code == 0, res.output
    assert json.loads(out.read_text())["pilot_settings"]["draws"] == 2
    assert json.loads(out.read_text())["episodes"][0]["pick"] == "central"
    res = CliRunner().invoke(app, ["eval", "closed-loop", "--pilot", "oracle-true", "--set", "draws=2", *grid])
    assert res.exit_code == 2 and "unknown planner option 'draws'" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(
        app, ["eval", "closed-loop", str(run.path), "--preset", "reference", *grid, "--json", str(out)]
    )
    assert res.exit_code == 0 and json.loads(out.read_text())["pilot_settings"]["timestep_spacing"] == "leading"
    assert json.loads(out.read_text())["preset"] == "reference"
    res = CliRunner().invoke(
        app, ["eval", "closed-loop", str(run.path), "--set", "noise_scale=0", *grid, "--json", str(out)]
    )
    assert res.exit_code == 0 and json.loads(out.read_text())["pilot_settings"]["noise_scale"] == 0, res.output
    res = CliRunner().invoke(app, ["eval", "closed-loop", str(run.path), "--set", "noise_scale=-1", *grid])
    assert res.exit_code == 2 and "noise_scale=-1" in res.output and "Traceback" not in res.output
    # a policy without the camera flies without rendering: the flight preset's codec has nothing to encode
    from dataclasses import replace

    blind = replace(PRESET, model=replace(PRESET.model, images=False))
    torch.manual_seed(0)
    blind_run = save_policy_run(DiffusionPolicy(blind.model), tmp_path / "blind", blind)
    res = CliRunner().invoke(app, ["eval", "closed-loop", str(blind_run.path), *grid, "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads(out.read_text())["image_codec"] is False


class ChunkPolicy(torch.nn.Module):
    """Stands in for a trained policy: sample k (0-based) is the chunk k * 100 + frame offset, so an
    executed action says which sample and which offset it came from; row i of a batch adds 10 i."""

    def __init__(self, rows: tuple[float, ...] | None = None):
        super().__init__()
        self.config, self.samples, self.noise_scales = PRESET.model, 0, []
        self.rows = rows  # the offset of each row of a batch (B,) or of each row and frame (B, H), when not 10 i

    def sample_actions(self, images, states, goal, generator=None, use_ema=True, sampling=None, noise=None):
        c = self.config
        self.noise_scales.append(sampling.noise_scale)
        chunk = torch.arange(c.horizon, dtype=torch.float32) - c.action_start + 100 * self.samples  # (H,)
        self.samples += 1
        rows = (
            10 * torch.arange(len(states), dtype=torch.float32)
            if self.rows is None
            else torch.as_tensor(self.rows, dtype=torch.float32)[: len(states)]
        )
        rows = rows[:, None].expand(-1, c.horizon) if rows.ndim == 1 else rows  # (B, H)
        return (chunk[None, :, None] + rows[:, :, None]).expand(len(states), c.horizon, c.action_dim)


def _fly_steps(pilot, steps: int) -> list[float]:
    obs = {"image": np.zeros((64, 64, 3), np.uint8), "state": np.zeros(16, np.float32)}
    pilot.reset(Task((1.0, 0.0, 0.0), 0.5, (0.0, 0.0, 0.0), 0))
    return [float(pilot.act(obs)[0]) for _ in range(steps)]


def test_action_steps_and_temporal_ensembling_are_honoured():
    chunked = DiffusionPilot(ChunkPolicy(), PolicySampling(action_steps=3))
    assert _fly_steps(chunked, 7) == [0, 1, 2, 100, 101, 102, 200] and chunked.policy.samples == 3
    assert _fly_steps(DiffusionPilot(ChunkPolicy(), PolicySampling()), 9)[7:] == [7, 100]  # the config's 8 by default
    ensembled = DiffusionPilot(ChunkPolicy(), PolicySampling(action_steps=1, ensemble=0.5))
    got = _fly_steps(ensembled, 3)
    w = np.exp(-0.5 * np.arange(3))  # frame 2: chunk 0's offset 2, chunk 1's offset 1, chunk 2's offset 0
    assert got[2] == pytest.approx(float(w @ np.array([2, 101, 200]) / w.sum()), rel=1e-6)
    assert ensembled.metadata() == {
        "preset": None,
        "action_steps": 1,
        "ensemble": 0.5,
        "draws": 1,
        "pick": "mean",
        "noise_scale": 1.0,
        "timestep_spacing": "leading",
        "inference_steps": PRESET.model.inference_steps,
        "image_codec": False,
    }
    averaged = DiffusionPilot(
        ChunkPolicy(), PolicySampling(action_steps=2, draws=3)
    )  # rows 0, 10, 20 of one call: their mean
    assert _fly_steps(averaged, 3) == [10, 11, 110] and averaged.policy.samples == 2
    assert averaged.metadata()["draws"] == 3
    with pytest.raises(ValueError, match="draws=0"):
        DiffusionPilot(ChunkPolicy(), PolicySampling(draws=0))
    # the central draw: the one nearest the draws' mean over the actions it executes (2 here: rows 0, 10 and
    # 40, mean 16.7, nearest 10), flown as drawn, though row 1 strays past them (1000 from frame t+2 on)
    rows = torch.tensor([0.0, 10.0, 40.0])[:, None].repeat(1, PRESET.model.horizon)
    rows[1, PRESET.model.action_start + 2 :] = 1000.0
    central = DiffusionPilot(ChunkPolicy(rows=rows), PolicySampling(action_steps=2, draws=3, pick="central"))
    assert _fly_steps(central, 3) == [10, 11, 110] and central.metadata()["pick"] == "central"
    with pytest.raises(ValueError, match="draws=N with N >= 2"):
        DiffusionPilot(ChunkPolicy(), PolicySampling(pick="central"))
    averaged = DiffusionPilot(ChunkPolicy(rows=(0.0, 10.0, 40.0)), PolicySampling(action_steps=2, draws=3))
    assert _fly_steps(averaged, 1)[0] == pytest.approx(50 / 3)
    with pytest.raises(ValueError, match="pick='median'"):
        DiffusionPilot(ChunkPolicy(), PolicySampling(draws=3, pick="median"))
    cooled = DiffusionPilot(
        ChunkPolicy(), PolicySampling(action_steps=2, noise_scale=0.25)
    )  # every chunk at that scale
    _fly_steps(cooled, 5)
    assert cooled.policy.noise_scales == [0.25] * 3 and cooled.metadata()["noise_scale"] == 0.25
    with pytest.raises(ValueError, match="noise_scale=-1"):
        DiffusionPilot(ChunkPolicy(), PolicySampling(noise_scale=-1))
    with pytest.raises(ValueError, match="action_steps=16"):
        DiffusionPilot(ChunkPolicy(), PolicySampling(action_steps=16))
