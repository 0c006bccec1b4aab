"""Training the Diffusion Policy on a tiny dataset: run folders, the goal join, exact resume
with EMA, checkpoint round trip, the open-loop evaluation, and one-line CLI errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitmodel.baselines.diffusion import train as T
from orbitmodel.baselines.diffusion.config import get_policy_preset
from orbitmodel.baselines.diffusion.evaluate import evaluate_policy
from orbitmodel.baselines.diffusion.expert_floor import expert_floor
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy
from orbitmodel.baselines.diffusion.sampling import PolicySampling, policy_sampling
from orbitmodel.cli.app import app
from orbitmodel.data import read_dataset_meta
from orbitmodel.runs import RunError, load_weights

torch.set_num_threads(1)
runner = CliRunner()
STEPS = 4
PRESET = get_policy_preset("tiny").with_train(max_steps=STEPS, save_every=2)
REFERENCE = policy_sampling("reference")  # the reference's sampler: leading spacing, as the tiny run trained


def request(dataset, out, **kw) -> T.PolicyRequest:
    return T.PolicyRequest(dataset=str(dataset), preset=PRESET, out=Path(out), device="cpu", **kw)


@pytest.fixture(scope="module")
def trained(tiny_dataset_master, tmp_path_factory) -> tuple[Path, list[dict]]:
    out = tmp_path_factory.mktemp("policy") / "run"
    logs = []
    T.train_policy(request(tiny_dataset_master, out), on_log=logs.append)
    return out, logs


def test_run_folder(trained):
    out, logs = trained
    config = json.loads((out / "config.json").read_text())
    assert config["stage"] == "policy" and config["policy"] == "diffusion"
    assert config["levels"] == ["expert"]
    assert config["preset"]["model"]["horizon"] == 16
    assert [r["step"] for r in logs] == list(range(1, STEPS + 1))
    assert all(np.isfinite(r["loss"]) for r in logs)
    assert (out / "model.safetensors").is_file()
    weights = load_file(out / "model.safetensors")
    ema = {k[len("ema.") :]: v for k, v in weights.items() if k.startswith("ema.")}
    net = {k[len("net.") :]: v for k, v in weights.items() if k.startswith("net.")}
    assert ema.keys() == net.keys()
    assert any(not torch.equal(ema[k], net[k]) for k in net)  # the EMA trails the weights


def test_checkpoint_round_trip(trained, tiny_dataset_master):
    out, _ = trained
    policy = DiffusionPolicy.from_pretrained(out)
    saved = load_weights(out)
    assert saved.keys() == policy.state_dict().keys()
    for k, v in policy.state_dict().items():
        assert torch.equal(v, saved[k]), k
    meta = read_dataset_meta(tiny_dataset_master)
    torch.testing.assert_close(policy.state_mean, torch.tensor(meta.state_mean))
    latest = (out / "checkpoints" / "latest").read_text().strip()
    assert latest == f"step-{STEPS:07d}"
    ckpt = load_file(out / "checkpoints" / latest / "model.safetensors")
    assert all(torch.equal(ckpt[k], saved[k]) for k in saved)


def test_resume_is_exact(trained, tiny_dataset_master, tmp_path):
    """Killed after the checkpoint at step 2 and resumed: the same weights and EMA as straight through."""
    out = tmp_path / "run"
    kill_after = Path(__file__).with_name("kill_after.py")  # SIGKILL right after the step-2 checkpoint
    cmd = [
        sys.executable,
        str(kill_after),
        "2",
        "train-policy",
        str(tiny_dataset_master),
        "--out",
        str(out),
        "--preset",
        "tiny",
        "--max-steps",
        str(STEPS),
        "--device",
        "cpu",
    ]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    # the CLI's tiny preset saves every 2 steps, as PRESET does
    assert get_policy_preset("tiny").train.loop.save_every == 2
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == -9, done.stderr[-2000:]
    assert not (out / "model.safetensors").exists()
    T.train_policy(request(tiny_dataset_master, out, resume=True))
    straight = load_file(trained[0] / "model.safetensors")
    resumed = load_file(out / "model.safetensors")
    for k in straight:
        assert torch.equal(straight[k], resumed[k]), k


def test_extend_trains_a_finished_run_on_under_the_longer_schedule(trained, tiny_dataset_master, tmp_path):
    """--resume --extend to more steps: the run goes on from its last checkpoint, the learning rate
    follows the longer schedule from there, and training.json records each segment's schedule."""
    import shutil

    from orbitmodel.train.loop import lr_at

    out = tmp_path / "run"
    shutil.copytree(trained[0], out)
    longer = PRESET.with_train(max_steps=STEPS + 2)
    logs = []
    T.train_policy(
        T.PolicyRequest(
            dataset=str(tiny_dataset_master), preset=longer, out=out, device="cpu", resume=True, extend=True
        ),
        on_log=logs.append,
    )
    assert [r["step"] for r in logs] == [STEPS + 1, STEPS + 2]
    settings = longer.train.loop
    assert [r["lr"] for r in logs] == pytest.approx([lr_at(s, STEPS + 2, settings) for s in (STEPS, STEPS + 1)])
    config = json.loads((out / "config.json").read_text())
    assert config["preset"]["train"]["loop"]["max_steps"] == STEPS + 2
    segments = json.loads((out / "training.json").read_text())["segments"]
    assert [(s["from_step"], s["to_step"], s["schedule_steps"]) for s in segments] == [
        (0, STEPS, STEPS),
        (STEPS, STEPS + 2, STEPS + 2),
    ]
    extended, ended = load_file(out / "model.safetensors"), load_file(trained[0] / "model.safetensors")
    assert any(not torch.equal(extended[k], ended[k]) for k in ended)  # trained on past the old end
    steps = [json.loads(r)["step"] for r in (out / "metrics.jsonl").read_text().splitlines()]
    assert steps == list(range(1, STEPS + 3))


def test_a_policy_run_with_a_flat_training_config_reads_back_and_extends(trained, tiny_dataset_master, tmp_path):
    """A config.json from before the loop settings were nested (runs on disk and on the Hub): the
    same preset reads back, and --resume --extend trains it on and rewrites it nested."""
    import shutil

    from orbitmodel.baselines.diffusion.config import read_policy_run

    out = tmp_path / "flat"
    shutil.copytree(trained[0], out)
    config = json.loads((out / "config.json").read_text())
    train = config["preset"]["train"]
    flat = {**{k: v for k, v in train.items() if k != "loop"}, **train["loop"]}
    (out / "config.json").write_text(json.dumps({**config, "preset": {**config["preset"], "train": flat}}))
    assert read_policy_run(out).preset == PRESET
    longer = PRESET.with_train(max_steps=STEPS + 1)
    T.train_policy(
        T.PolicyRequest(
            dataset=str(tiny_dataset_master), preset=longer, out=out, device="cpu", resume=True, extend=True
        )
    )
    rewritten = json.loads((out / "config.json").read_text())["preset"]["train"]
    assert rewritten == json.loads(json.dumps(longer.train.to_dict())) and rewritten["loop"]["max_steps"] == STEPS + 1
    assert json.loads((out / "training.json").read_text())["segments"][-1]["to_step"] == STEPS + 1


def test_extend_refuses_what_is_not_a_longer_run(trained, tiny_dataset_master, tmp_path):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(trained[0], out)
    before = (out / "model.safetensors").read_bytes()
    cases = {  # args -> what the one line must say
        ("--max-steps", str(STEPS + 2), "--extend"): "--extend continues a run",  # no --resume
        ("--max-steps", str(STEPS + 2), "--resume", "--extend", "--lr", "0.01"): "larger --max-steps only",
        ("--max-steps", str(STEPS - 1), "--resume", "--extend"): "larger --max-steps only",
        ("--max-steps", str(STEPS + 2), "--resume"): "another config",  # a longer run needs --extend
        ("--max-steps", str(STEPS), "--resume", "--extend"): "already trained to its --max-steps",
        ("--max-steps", "10000000", "--resume", "--extend"): "epochs end at step",  # past the run's epochs
    }
    for args, says in cases.items():
        result = runner.invoke(
            app,
            ["train-policy", str(tiny_dataset_master), "--out", str(out), "--preset", "tiny", "--device", "cpu", *args],
        )
        assert result.exit_code == 2, (args, result.output)
        assert says in result.output and "Traceback" not in result.output, (args, result.output)
    assert (out / "model.safetensors").read_bytes() == before  # nothing written is lost


def test_the_state_only_variant_trains_and_evaluates_without_images(tiny_dataset_master, tmp_path):
    blind = replace(PRESET, model=replace(PRESET.model, images=False))
    windows = T.policy_windows(tiny_dataset_master, "train", blind, {"level": ["expert"]})
    assert S.IMAGE not in windows[0]  # no image decoded
    out = tmp_path / "run"
    T.train_policy(T.PolicyRequest(dataset=str(tiny_dataset_master), preset=blind, out=out, device="cpu"))
    assert json.loads((out / "config.json").read_text())["preset"]["model"]["images"] is False
    policy = DiffusionPolicy.from_pretrained(out)
    assert policy.net.obs_encoder.image is None
    result = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8)
    assert result.frames > 0 and np.isfinite(result.policy)
    assert get_policy_preset("cpu-state").model == replace(get_policy_preset("cpu").model, images=False)


def test_the_privileged_diagnostic_reads_the_true_obstacles_and_cannot_fly(trained, tiny_dataset_master, tmp_path):
    """preset cpu-state-obstacles' kind: told each episode's true obstacles (centre, bounding radius),
    trained and scored open loop like any policy; no pilot flies it."""
    from orbitdata.scenario.spec import Obstacle
    from orbitmodel.baselines.diffusion.pilot import DiffusionPilot

    trained_run = trained[0]
    told = replace(PRESET, model=replace(PRESET.model, images=False, obstacles=5))
    lookup = T.episode_obstacles(tiny_dataset_master, "train", 5)
    table = T.load_episode_table(tiny_dataset_master, "train", {})
    for idx, row in zip(table.column(S.EPISODE_INDEX).to_pylist(), table.column(S.OBSTACLES).to_pylist()):
        want = [
            [*o["center"], Obstacle(o["shape"], tuple(o["center"]), tuple(o["size"])).bounding_radius] for o in row[:5]
        ]
        np.testing.assert_allclose(
            lookup[idx, : len(want)].numpy(), np.asarray(want, np.float32).reshape(-1, 4), rtol=1e-6
        )
        assert not lookup[idx, len(want) :].any()  # empty slots
    out = tmp_path / "run"
    T.train_policy(T.PolicyRequest(dataset=str(tiny_dataset_master), preset=told, out=out, device="cpu"))
    policy = DiffusionPolicy.from_pretrained(out)
    result = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8)
    assert result.frames > 0 and np.isfinite(result.policy)
    blind = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8, without_obstacles=True)
    assert blind.frames == result.frames and blind.policy != result.policy  # the same windows, told nothing
    assert blind.without_obstacles and not result.without_obstacles  # the report says which it is
    res = runner.invoke(app, ["eval", "policy", str(trained_run), str(tiny_dataset_master), "--without-obstacles"])
    assert res.exit_code == 2 and "told no obstacles" in res.output and "Traceback" not in res.output
    states = torch.zeros(1, 2, 16)
    states[..., 6] = states[..., 9] = 1.0
    goal, obstacles = torch.tensor([[3.0, 0.0, 0.0]]), torch.zeros(1, 5, 4)
    obstacles[0, 0] = torch.tensor([1.5, 0.2, 0.0, 0.4])
    moved = obstacles.clone()
    moved[0, 0, 1] = -0.2  # the same obstacle on the other side
    cond = [policy.condition(policy.ema, None, states, goal, o) for o in (obstacles, moved)]
    assert not torch.equal(cond[0], cond[1])
    with pytest.raises(ValueError, match="privileged"):
        policy.condition(policy.ema, None, states, goal)
    with pytest.raises(ValueError, match="cannot fly"):
        DiffusionPilot(policy)


def test_goal_join_reads_only_goals(tiny_dataset_master, monkeypatch):
    table = T.load_episode_table(tiny_dataset_master, "train", {})
    monkeypatch.setattr(T, "load_episode_table", lambda *a: table.drop_columns([S.OBSTACLES]))
    goals = T.episode_goals(tiny_dataset_master, "train")
    for idx, goal in zip(table.column(S.EPISODE_INDEX).to_pylist(), table.column(S.GOAL).to_pylist()):
        np.testing.assert_allclose(goals[idx].numpy(), goal, rtol=1e-6)
    assert S.OBSTACLES not in T.COLUMNS
    windows = T.policy_windows(tiny_dataset_master, "train", PRESET, {"level": list(T.DEFAULT_LEVELS)})
    levels = dict(zip(table.column(S.EPISODE_INDEX).to_pylist(), table.column(S.LEVEL).to_pylist()))
    assert {levels[int(e)] for e in windows.episodes} == {"expert"}
    item = windows[0]
    assert item[S.ACTION].shape == (16, 8) and item[S.IMAGE].shape == (2, 3, 64, 64)  # observed frames only


def test_job_inputs(tiny_dataset_master):
    meta = read_dataset_meta(tiny_dataset_master)
    policy = T.build_policy(PRESET, meta)
    windows = T.policy_windows(tiny_dataset_master, "train", PRESET, {"level": list(T.DEFAULT_LEVELS)})
    from orbitdata.load import collate_windows

    batch = collate_windows(windows.__getitems__([0, 1, 2]))
    job = T.PolicyJob(policy, PRESET, T.episode_goals(tiny_dataset_master, "train"))
    inputs = job.inputs(batch, step=0, device=torch.device("cpu"))
    assert set(inputs) == {"images", "states", "goal", "actions", "real", "generator"}
    assert inputs["images"].shape == (3, 2, 3, 64, 64) and inputs["images"].dtype == torch.uint8
    assert inputs["states"].shape == (3, 2, 16) and inputs["goal"].shape == (3, 3)
    assert not torch.isnan(inputs["goal"]).any()
    again = job.inputs(batch, step=0, device=torch.device("cpu"))
    assert torch.equal(inputs["images"], again["images"])  # augmentation seeded by the step
    with pytest.raises(RunError, match="32 px"):
        T.build_policy(replace(PRESET, model=replace(PRESET.model, image_size=32)), meta)


def test_evaluate(trained, tiny_dataset_master):
    out, _ = trained
    result = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8, sampling=REFERENCE)
    assert result.windows > 0 and result.frames > 0
    assert np.isfinite(result.policy) and result.mean_action > 0
    again = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8, sampling=REFERENCE)
    assert again == result  # seeded sampling
    # the same frames, split by executed index and by distance to the goal: the parts add up to the whole
    for parts in (result.per_index, result.per_band):
        assert sum(r["frames"] for r in parts) == result.frames
        total = sum(r["policy"] * r["frames"] for r in parts if r["frames"])
        assert total / result.frames == pytest.approx(result.policy, rel=1e-9)
    assert [r["index"] for r in result.per_index] == list(range(8))
    assert [(r["from_m"], r["to_m"]) for r in result.per_band] == [(0, 1), (1, 2), (2, 4), (4, 8), (8, None)]
    # several draws: the first is the one scored alone; over the draws, a draw's error is the error of
    # their mean plus (N-1)/N of their variance, in every band
    three = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8, sampling=replace(REFERENCE, draws=3))
    assert (
        three.samples == 3
        and three.policy == result.policy
        and three.per_band[0]["policy"] == result.per_band[0]["policy"]
    )
    for r in three.per_band + three.per_index:
        if r["frames"]:
            assert r["draws"] == pytest.approx(r["sample_mean"] + 2 / 3 * r["variance"], rel=1e-5)
            assert r["variance"] > 0
    assert three.draws == pytest.approx(three.sample_mean + 2 / 3 * three.variance, rel=1e-5)
    # draws started from zero noise are one deterministic chunk: no variance, whatever the seed
    still = evaluate_policy(
        out, tiny_dataset_master, stride=8, batch_size=8, sampling=replace(REFERENCE, draws=3, noise_scale=0.0)
    )
    assert still.variance == 0 and still.noise_scale == 0 and still.draws == pytest.approx(still.policy, rel=1e-6)
    assert still.central == pytest.approx(still.policy, rel=1e-6)  # every draw is central when all are one chunk
    # the default is the reported flight preset (cpu: trailing spacing), recorded and sampled with
    trailing = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8)
    assert (result.timestep_spacing, trailing.timestep_spacing, trailing.preset) == ("leading", "trailing", "cpu")
    assert trailing.policy != result.policy and trailing.frames == result.frames
    two = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8, sampling=PolicySampling(inference_steps=2))
    assert two.inference_steps == 2
    assert three.central is not None and all(r["central_ratio"] is not None for r in three.per_band if r["frames"])
    assert (
        still.policy
        == evaluate_policy(
            out, tiny_dataset_master, stride=8, batch_size=8, seed=5, sampling=replace(REFERENCE, noise_scale=0.0)
        ).policy
    )
    for bad in ("inf", "-1", "cold"):
        cli = runner.invoke(app, ["eval", "policy", str(out), str(tiny_dataset_master), "--set", f"noise_scale={bad}"])
        assert cli.exit_code == 2 and "noise_scale" in cli.output and "Traceback" not in cli.output, cli.output
    cli = runner.invoke(
        app,
        [
            "eval",
            "policy",
            str(out),
            str(tiny_dataset_master),
            "--stride",
            "8",
            "--json",
            "--device",
            "cpu",
            "--max-windows",
            "3",
            "--set",
            "noise_scale=0.5",
        ],
    )
    assert cli.exit_code == 0, cli.output
    reported = json.loads(cli.stdout.strip().splitlines()[-1])
    assert reported["windows"] == 3 and reported["noise_scale"] == 0.5 and reported["preset"] == "cpu"
    cli = runner.invoke(
        app,
        [
            "eval",
            "policy",
            str(out),
            str(tiny_dataset_master),
            "--stride",
            "8",
            "--json",
            "--device",
            "cpu",
            "--max-windows",
            "3",
            "--preset",
            "reference",
            "--set",
            "inference_steps=2",
            "--set",
            "draws=2",
        ],
    )
    assert cli.exit_code == 0, cli.output
    reported = json.loads(cli.stdout.strip().splitlines()[-1])
    assert (reported["timestep_spacing"], reported["inference_steps"], reported["samples"]) == ("leading", 2, 2)
    cli = runner.invoke(app, ["eval", "policy", str(out), str(tiny_dataset_master), "--preset", "paper"])
    assert cli.exit_code == 2 and "unknown policy flight preset 'paper'" in cli.output
    cli = runner.invoke(app, ["eval", "policy", str(out), str(tiny_dataset_master), "--stride", "8", "--device", "cpu"])
    assert cli.exit_code == 0 and "by executed index" in cli.output and "t+7" in cli.output and ">= 8 m" in cli.output


def test_the_central_draw_is_scored_as_drawn(trained, tiny_dataset_master, monkeypatch):
    """--set draws=3 with draws that are constant chunks 0, 0.3 and 1 (in that order, every window):
    the central draw, nearest their mean 0.43, is the 0.3 chunk, scored as a policy that always says 0.3."""
    out, _ = trained
    values, calls = [], []

    def constant(self, images, states, goal, generator=None, use_ema=True, obstacles=None, sampling=None):
        calls.append(values[len(calls) % len(values)])
        return torch.full((len(states), self.config.horizon, self.config.action_dim), calls[-1])

    monkeypatch.setattr(DiffusionPolicy, "sample_actions", constant)
    values[:] = [0.0, 0.3, 1.0]
    three = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8, sampling=PolicySampling(draws=3))
    values[:], calls[:] = [0.3], []
    fixed = evaluate_policy(out, tiny_dataset_master, stride=8, batch_size=8)
    assert three.central == pytest.approx(fixed.policy, rel=1e-6) and three.central != three.policy
    for r, f in zip(three.per_band, fixed.per_band):
        assert r["central"] == (pytest.approx(f["policy"], rel=1e-6) if r["frames"] else None)


def test_expert_floor_scores_other_plans_where_the_policy_is_scored(trained, tiny_dataset_master):
    """Other RRT* plans of each episode's task that pass by the state at frame t act at the recorded
    states; the policy is scored on exactly those windows and frames."""
    out, _ = trained
    floor = expert_floor(out, tiny_dataset_master, stride=8, plans=4, position_m=0.5, speed_mps=0.5, angle_deg=60.0)
    assert 0 < floor.scored_windows <= floor.windows and floor.frames > 0 and floor.plans_per_window >= 1
    assert floor.policy["windows"] == floor.scored_windows and floor.policy["frames"] == floor.frames
    for parts in (floor.per_index, floor.per_band):
        assert sum(r["frames"] for r in parts) == floor.frames
        for name in ("other", "own", "mean_action"):
            total = sum(r[name] * r["frames"] for r in parts if r["frames"])
            assert total / floor.frames == pytest.approx(getattr(floor, name), rel=1e-9)
    # the episode's own plan taken up at its recorded states differs from the record by thrust noise only
    assert 0 < floor.own < 0.25 * floor.mean_action
    assert 0.5 <= floor.own_plan_could <= 1
    assert (
        expert_floor(out, tiny_dataset_master, stride=8, plans=4, position_m=0.5, speed_mps=0.5, angle_deg=60.0)
        == floor
    )
    cli = runner.invoke(
        app,
        [
            "eval",
            "expert-floor",
            str(out),
            str(tiny_dataset_master),
            "--stride",
            "8",
            "--plans",
            "4",
            "--position-m",
            "0.5",
            "--speed-mps",
            "0.5",
            "--angle-deg",
            "60",
            "--json",
            "--device",
            "cpu",
        ],
    )
    assert cli.exit_code == 0, cli.output
    assert json.loads(cli.stdout.strip().splitlines()[-1]) == json.loads(json.dumps(floor.to_dict()))
    cli = runner.invoke(
        app,
        [
            "eval",
            "expert-floor",
            str(out),
            str(tiny_dataset_master),
            "--stride",
            "8",
            "--plans",
            "4",
            "--position-m",
            "0.5",
            "--speed-mps",
            "0.5",
            "--angle-deg",
            "60",
            "--no-policy",
        ],
    )
    assert cli.exit_code == 0 and "another expert" in cli.output and "policy" not in cli.output, cli.output
    assert "tolerances" in one_line_error(
        ["eval", "expert-floor", str(out), str(tiny_dataset_master), "--position-m", "0"]
    )
    assert "drop one" in one_line_error(
        ["eval", "expert-floor", str(out), str(tiny_dataset_master), "--no-policy", "--preset", "cpu"]
    )


def one_line_error(args) -> str:
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    lines = [r for r in result.stderr.splitlines() if r.startswith("error:")]
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.output
    return lines[0]


def test_clear_errors(trained, tiny_dataset_master, tmp_path):
    out, _ = trained
    assert "no dataset folder" in one_line_error(["train-policy", str(tmp_path / "nope"), "--out", str(tmp_path / "r")])
    assert "--resume" in one_line_error(
        [
            "train-policy",
            str(tiny_dataset_master),
            "--out",
            str(tmp_path / "r2"),
            "--preset",
            "tiny",
            "--resume",
            "--device",
            "cpu",
        ]
    )
    assert "another config" in one_line_error(
        ["train-policy", str(tiny_dataset_master), "--out", str(out), "--preset", "tiny", "--device", "cpu"]
    )
    world = tmp_path / "wm"
    world.mkdir()
    (world / "config.json").write_text(json.dumps({"stage": "world_model"}))
    assert "not a diffusion policy" in one_line_error(["eval", "policy", str(world), str(tiny_dataset_master)])
    assert "not an orbitmodel run" in one_line_error(["eval", "policy", str(tmp_path), str(tiny_dataset_master)])
    assert "exploratory" in one_line_error(
        ["eval", "policy", str(out), str(tiny_dataset_master), "--level", "exploratory", "--device", "cpu"]
    )


def test_padded_and_terminal_frames_add_no_loss(tiny_dataset_master, monkeypatch):
    """Windows that run past an episode's end: the loss has no term for their terminal and padded
    frames (a denoiser that answers the same whatever it is shown makes the terms visible), and it
    does have one for every real frame."""
    from orbitdata.load import collate_windows

    preset = replace(PRESET, model=replace(PRESET.model, prediction_type="sample"))  # the target is the actions
    policy = T.build_policy(preset, read_dataset_meta(tiny_dataset_master)).eval()
    monkeypatch.setattr(policy.net.unet, "forward", lambda sample, step, cond: torch.zeros_like(sample))
    windows = T.policy_windows(tiny_dataset_master, "train", preset, None)
    ends = [i for i in range(len(windows)) if windows[i]["is_pad"].any()][:4]  # windows past an episode's end
    batch = collate_windows(windows.__getitems__(ends))
    inputs = T.PolicyJob(policy, preset, T.episode_goals(tiny_dataset_master, "train")).inputs(
        batch, 0, torch.device("cpu")
    )
    real = inputs["real"]
    assert ends and (~real).any() and real.any()

    def loss(actions):
        return float(
            policy.loss(
                inputs["images"], inputs["states"], inputs["goal"], actions, torch.Generator().manual_seed(0), real
            )[0]
        )

    base = loss(inputs["actions"])
    changed = inputs["actions"].clone()
    changed[~real] = torch.rand(int((~real).sum()), 8, generator=torch.Generator().manual_seed(1))
    assert loss(changed) == pytest.approx(base, rel=1e-6)
    changed[real] = 1.0 - changed[real]
    assert abs(loss(changed) - base) > 1e-3


def test_windows_that_start_before_the_first_frame(tiny_dataset_master):
    """pad_before: per episode, a window whose first observation repeats frame 0 (as the pilot's
    first step does), its padded frame marked, batched and single alike."""
    from orbitdata.load import collate_windows

    plain = T.policy_windows(tiny_dataset_master, "train", PRESET, None)
    padded = T.policy_windows(tiny_dataset_master, "train", PRESET, None, pad_before=1)
    episodes = sorted(set(plain.index.episode.tolist()))
    assert len(padded) == len(plain) + len(episodes)
    first = next(i for i in range(len(plain)) if int(plain[i][S.FRAME_INDEX][0]) == 0)
    extra = next(j for j in range(len(plain), len(padded)) if padded.extra[j - len(plain)][0] == first)
    a, b = plain[first], padded[extra]
    assert b[S.FRAME_INDEX].tolist() == [0] + a[S.FRAME_INDEX].tolist()[:-1]
    assert torch.equal(b[S.IMAGE][0], b[S.IMAGE][1]) and torch.equal(b[S.ACTION][1:], a[S.ACTION][:-1])
    assert b["is_pad"][0] and not b["is_pad"][1]
    batch = collate_windows(padded.__getitems__([first, extra]))
    assert torch.equal(batch[S.ACTION][1], b[S.ACTION]) and torch.equal(batch[S.ACTION][0], a[S.ACTION])
    assert len(list(padded.sampler(seed=0))) == len(padded)


def test_a_policy_run_from_before_padding_and_masking_resumes_with_its_own_recipe(tiny_dataset_master, tmp_path):
    """Its config.json lacks pad_before, mask_padding and the validation split: --resume takes it
    for what it was (no padding, no masking), and refuses to continue it with another recipe."""
    out = tmp_path / "old"
    args = [
        "train-policy",
        str(tiny_dataset_master),
        "--preset",
        "tiny",
        "--max-steps",
        "2",
        "--device",
        "cpu",
        "--out",
        str(out),
    ]
    assert runner.invoke(app, [*args, "--pad-before", "0", "--no-mask-padding"]).exit_code == 0
    config = json.loads((out / "config.json").read_text())
    for key in ("pad_before", "mask_padding", "val_fraction", "val_seed"):
        del config["preset"]["train"][key]
    del config["validation"]
    config["preset"]["description"] = "a few thousand parameters, for tests"  # the earlier wording
    (out / "config.json").write_text(json.dumps(config))
    (out / "model.safetensors").unlink()
    assert "another config" in one_line_error([*args, "--resume"])  # today's defaults are another recipe
    res = runner.invoke(app, [*args, "--resume", "--pad-before", "0", "--no-mask-padding"])
    assert res.exit_code == 0, res.output
    assert (out / "model.safetensors").is_file()
