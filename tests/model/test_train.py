"""``orbitmodel train``: the loss falls, checkpoints round-trip, a killed run resumes exactly,
DDP runs on two CPU processes, and bad input gets one line and exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file
from typer.testing import CliRunner

from orbitmodel.cli.app import app
from orbitmodel.config import get_preset
from orbitmodel.model.world_model import WorldModel
from orbitmodel.runs import RunError
from orbitmodel.train.stage1 import Stage1Request, train_world_model

runner = CliRunner()


KILL_AFTER = Path(__file__).with_name("kill_after.py")


def _cli(*args: str, env: dict | None = None, kill_after: int | None = None) -> subprocess.CompletedProcess:
    """The CLI in a fresh process; ``kill_after``: SIGKILLed right after that step's checkpoint."""
    launch = ["-m", "orbitmodel.cli.app"] if kill_after is None else [str(KILL_AFTER), str(kill_after)]
    return subprocess.run(
        [sys.executable, *launch, *args], capture_output=True, text=True, env={**os.environ, **(env or {})}, timeout=300
    )


def _train(dataset, out, steps: int, **train) -> None:
    preset = get_preset("tiny").with_train(max_steps=steps, **train)
    train_world_model(Stage1Request(dataset=str(dataset), preset=preset, out=out, device="cpu"))


@pytest.fixture(scope="module")
def trained(tiny_dataset_master, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "wm"
    _train(tiny_dataset_master, out, steps=30, save_every=10, log_every=1)
    return out


def test_training_lowers_the_loss(trained):
    losses = [json.loads(line)["loss"] for line in (trained / "metrics.jsonl").read_text().splitlines()]
    assert len(losses) == 30
    assert sum(losses[-5:]) / 5 < 0.7 * sum(losses[:5]) / 5


def test_metrics_carry_the_three_losses_and_the_data_wait(trained):
    record = json.loads((trained / "metrics.jsonl").read_text().splitlines()[-1])
    for key in ("step", "lr", "loss", "pred", "sigreg", "depth", "grad_norm", "windows_per_s", "data_wait"):
        assert key in record
    assert 0 <= record["data_wait"] <= 1


def test_checkpoint_round_trip(trained):
    model = WorldModel.from_pretrained(trained)
    assert not model.training
    weights = load_file(trained / "model.safetensors")
    for name, value in model.state_dict().items():
        torch.testing.assert_close(value, weights[name], rtol=0, atol=0)
    fresh = WorldModel(get_preset("tiny").model)
    assert not torch.equal(fresh.state_dict()["encoder.pos"], model.state_dict()["encoder.pos"])
    assert model.run_info.image_size == 64 and len(model.run_info.state_mean) == 16
    assert torch.allclose(model.state_mean, torch.tensor(model.run_info.state_mean))


def test_a_killed_run_resumes_to_the_same_weights(tiny_dataset_master, tmp_path):
    common = ["train", str(tiny_dataset_master), "--preset", "tiny", "--max-steps", "8", "--device", "cpu"]
    straight = _cli(*common, "--out", str(tmp_path / "a"))
    assert straight.returncode == 0, straight.stderr
    killed = _cli(*common, "--out", str(tmp_path / "b"), kill_after=4)
    assert killed.returncode == -9  # SIGKILL right after the step-4 checkpoint
    assert not (tmp_path / "b" / "model.safetensors").exists()
    assert (tmp_path / "b" / "checkpoints" / "latest").read_text().strip() == "step-0000004"
    resumed = _cli(*common, "--out", str(tmp_path / "b"), "--resume")
    assert resumed.returncode == 0, resumed.stderr
    a = load_file(tmp_path / "a" / "model.safetensors")
    b = load_file(tmp_path / "b" / "model.safetensors")
    assert a.keys() == b.keys()
    for name in a:
        assert torch.equal(a[name], b[name]), name
    steps = [json.loads(r)["step"] for r in (tmp_path / "b" / "metrics.jsonl").read_text().splitlines()]
    assert steps == list(range(1, 9))  # no step logged twice


class _Cut(Exception):
    pass


def test_a_run_cut_before_its_first_checkpoint_starts_again_resumed_or_not(tiny_dataset_master, tmp_path):
    """A chain that reruns `train` after a kill must not meet "pass --resume" and then "no checkpoint yet":
    the folder holds only its config (and a logged step), nothing trained to lose."""
    _train(tiny_dataset_master, tmp_path / "straight", steps=6, save_every=4, log_every=1)

    def cut(record):
        if record["step"] == 2:
            raise _Cut  # before the first checkpoint, at step 4

    for name, resume in (("again", False), ("resumed", True)):
        preset = get_preset("tiny").with_train(max_steps=6, save_every=4, log_every=1)
        req = Stage1Request(dataset=str(tiny_dataset_master), preset=preset, out=tmp_path / name, device="cpu")
        with pytest.raises(_Cut):
            train_world_model(req, on_log=cut)
        assert (tmp_path / name / "config.json").exists() and not (tmp_path / name / "checkpoints").exists()
        train_world_model(Stage1Request(**{**req.__dict__, "resume": resume}))
        a, b = load_file(tmp_path / "straight" / "model.safetensors"), load_file(tmp_path / name / "model.safetensors")
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a), name
        steps = [json.loads(r)["step"] for r in (tmp_path / name / "metrics.jsonl").read_text().splitlines()]
        assert steps == list(range(1, 7)), name  # the cut run's logged steps are not kept twice
    # a trained run still refuses to be trained over without a word, and a resume with nothing to
    # continue from names the way out
    trained = Stage1Request(**{**req.__dict__, "out": tmp_path / "again"})
    with pytest.raises(RunError, match="already holds this run; pass --resume"):
        train_world_model(trained)
    (tmp_path / "again" / "checkpoints" / "latest").unlink()  # its checkpoints, no longer pointed at
    with pytest.raises(RunError, match=r"no checkpoint to continue from \(no checkpoints/latest\); pass --overwrite"):
        train_world_model(Stage1Request(**{**trained.__dict__, "resume": True}))
    (tmp_path / "again" / "model.safetensors").unlink()  # and no final weights: the checkpoints still count
    for resume, says in ((False, "already holds this run"), (True, "no checkpoint to continue from")):
        with pytest.raises(RunError, match=says):  # a restart from step 0 would prune those checkpoints
            train_world_model(Stage1Request(**{**trained.__dict__, "resume": resume}))


def test_ddp_on_two_cpu_processes(tiny_dataset_master, tmp_path):
    out = tmp_path / "ddp"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "torch.distributed.run",
            "--nproc_per_node",
            "2",
            "--master_port",
            "29517",
            "-m",
            "orbitmodel.cli.app",
            "train",
            str(tiny_dataset_master),
            "--preset",
            "tiny",
            "--max-steps",
            "3",
            "--device",
            "cpu",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    records = [json.loads(r) for r in (out / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == [1, 2, 3]  # rank 0 alone writes
    assert records[-1]["world_size"] == 2
    assert (out / "model.safetensors").exists()


def test_training_is_reproducible_from_the_seed(tiny_dataset_master, tmp_path):
    _train(tiny_dataset_master, tmp_path / "a", steps=3)
    _train(tiny_dataset_master, tmp_path / "b", steps=3)
    a, b = load_file(tmp_path / "a" / "model.safetensors"), load_file(tmp_path / "b" / "model.safetensors")
    assert all(torch.equal(a[k], b[k]) for k in a)


# ---- bad input: one line, exit 2 ---------------------------------------------------------------
def _one_line_exit_2(result, *needles: str) -> None:
    assert result.exit_code == 2, result.output
    lines = [r for r in result.output.splitlines() if r.strip()]
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_an_out_folder_that_is_a_file(tiny_dataset_master, tmp_path):
    (tmp_path / "taken").write_text("a result")
    for out in ("taken", "taken/run"):
        result = runner.invoke(app, ["train", str(tiny_dataset_master), "--out", str(tmp_path / out)])
        _one_line_exit_2(result, f"{tmp_path / 'taken'} is a file; give another folder")
    assert (tmp_path / "taken").read_text() == "a result"


def test_a_window_longer_than_every_episode_names_the_flag_and_what_fits(tiny_dataset_master, tmp_path):
    run = tmp_path / "r"
    result = runner.invoke(
        app, ["train", str(tiny_dataset_master), "--preset", "tiny", "--window", "1000", "--out", str(run)]
    )
    _one_line_exit_2(result, "--window 1000: a window of 1000 steps of 1 frame is longer than", "give --window")
    assert "pad=True" not in result.output and not run.exists()  # nothing claimed: another --window just runs


def test_missing_dataset(tmp_path):
    _one_line_exit_2(runner.invoke(app, ["train", str(tmp_path / "nope"), "--out", str(tmp_path / "r")]), "nope")


def test_folder_that_is_not_a_dataset(tmp_path):
    """A folder generate never wrote is not told to run generate "again"; one it left unfinished is."""
    from orbitdata import schema as S

    (tmp_path / "plain").mkdir()
    _one_line_exit_2(
        runner.invoke(app, ["train", str(tmp_path / "plain"), "--out", str(tmp_path / "r")]),
        "not a finished orbitdata dataset; give a folder made by `orbitdata generate`",
    )
    (tmp_path / "plain" / S.PARTS_DIR).mkdir()
    _one_line_exit_2(
        runner.invoke(app, ["train", str(tmp_path / "plain"), "--out", str(tmp_path / "r")]),
        "a `generate` run into it did not finish: run the same command again",
    )


def test_image_size_the_preset_cannot_take(tiny_dataset_master, tmp_path):
    result = runner.invoke(app, ["train", str(tiny_dataset_master), "--preset", "paper", "--out", str(tmp_path / "r")])
    _one_line_exit_2(result, "224 px", "64 px", "--image-size 224")


def test_unknown_preset(tiny_dataset_master, tmp_path):
    result = runner.invoke(app, ["train", str(tiny_dataset_master), "--preset", "huge", "--out", str(tmp_path / "r")])
    assert result.exit_code == 2 and "huge" in result.output


def test_a_diverging_run_stops_without_saving_its_weights(tiny_dataset_master, tmp_path):
    run = tmp_path / "r"
    args = [
        "train",
        str(tiny_dataset_master),
        "--preset",
        "tiny",
        "--max-steps",
        "4",
        "--lr",
        "1e12",
        "--out",
        str(run),
    ]
    res = runner.invoke(app, args)
    last = [line for line in res.output.splitlines() if line.strip()][-1]  # after the progress lines
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert last.startswith(f"error: {run}: the loss or its gradient became nan or inf by step"), last
    assert "a lower --lr (this run's: 1e+12)" in last
    assert not (run / "model.safetensors").exists() and not (run / "checkpoints").exists()


def test_run_folder_with_another_config_needs_overwrite(tiny_dataset_master, trained, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(trained, run)
    args = ["train", str(tiny_dataset_master), "--preset", "tiny", "--max-steps", "2", "--out", str(run)]
    _one_line_exit_2(runner.invoke(app, args), "another config", "--overwrite")
    assert runner.invoke(app, [*args, "--overwrite"]).exit_code == 0
    assert runner.invoke(app, [*args, "--window", "4", "--overwrite"]).exit_code == 0
    assert json.loads((run / "config.json").read_text())["preset"]["train"]["window"] == 4  # the flag, recorded


@pytest.mark.parametrize("command", ["train", "train-policy"])
def test_threads_sets_the_torch_threads_the_run_records(tiny_dataset_master, tmp_path, command):
    """--threads N trains on N torch threads (beside other work), and training.json says so."""
    before = torch.get_num_threads()
    threads = 2 if before == 1 else 1
    run = tmp_path / "run"
    args = [command, str(tiny_dataset_master), "--preset", "tiny", "--max-steps", "1", "--device", "cpu"]
    try:
        res = runner.invoke(app, [*args, "--threads", str(threads), "--out", str(run)])
    finally:
        torch.set_num_threads(before)
    assert res.exit_code == 0, res.output
    segments = json.loads((run / "training.json").read_text())["segments"]
    assert segments[-1]["hardware"].endswith(f"{threads} torch threads"), segments


def test_a_run_resumes_whatever_the_spelling_of_its_dataset_path(tmp_path, monkeypatch):
    """`train toy --out r`, then `train ./toy --out r --resume` (or the absolute path): one run."""
    from orbitmodel.runs import RunDir

    (tmp_path / "toy").mkdir()
    monkeypatch.chdir(tmp_path)
    run = RunDir(tmp_path / "run")
    config = {"stage": "world_model", "dataset": {"source": "toy", "image_size": 64}, "preset": {"name": "tiny"}}
    run.start(config, resume=False, overwrite=False)
    for spelling in ("./toy", str(tmp_path / "toy"), "toy/"):
        run.start({**config, "dataset": {**config["dataset"], "source": spelling}}, resume=True, overwrite=False)
    with pytest.raises(
        RunError,
        match=r"differs in: dataset.source: 'toy/' -> 'elsewhere'\); give the run's own settings to continue it",
    ):
        run.start({**config, "dataset": {**config["dataset"], "source": "elsewhere"}}, resume=True, overwrite=False)
    with pytest.raises(RunError, match=r"differs in: preset.name: 'tiny' -> 'cpu'\); give the run's own settings"):
        run.start({**config, "preset": {"name": "cpu"}}, resume=True, overwrite=False)
    with pytest.raises(RunError, match=r"differs in: preset.name: 'tiny' -> 'cpu'\); pass --overwrite to replace it"):
        RunDir(tmp_path / "run").start({**config, "preset": {"name": "cpu"}}, resume=False, overwrite=False)


def test_a_corrupt_checkpoint_is_one_line(trained, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(trained, run)
    (run / "model.safetensors").write_bytes(b"\x00" * 100)
    with pytest.raises(RunError, match="corrupt"):
        WorldModel.from_pretrained(run)
    result = runner.invoke(app, ["eval", "rollout", str(run), str(run)])
    _one_line_exit_2(result, "corrupt")


def test_resume_without_a_run(tiny_dataset_master, tmp_path):
    result = runner.invoke(
        app, ["train", str(tiny_dataset_master), "--preset", "tiny", "--resume", "--out", str(tmp_path / "empty")]
    )
    _one_line_exit_2(result, "--resume")


def test_training_writes_tensorboard_event_files(trained):
    import tensorboard  # noqa: F401  the test extra installs it: a broken import fails here, it is not skipped

    events = list((trained / "tensorboard").glob("events.out.tfevents.*"))
    assert events and events[0].stat().st_size > 0


def test_sigreg_flags_override_the_preset_and_land_in_the_run_config(tiny_dataset_master, tmp_path):
    from orbitmodel.runs import read_run_config

    run = tmp_path / "run"
    args = [
        "train",
        str(tiny_dataset_master),
        "--preset",
        "tiny",
        "--max-steps",
        "1",
        "--out",
        str(run),
        "--lambda-sigreg",
        "0.7",
        "--sigreg-pool",
    ]
    assert runner.invoke(app, args).exit_code == 0
    model = read_run_config(run).preset.model
    assert (model.lambda_sigreg, model.sigreg_pool) == (0.7, True)
    assert not get_preset("tiny").model.sigreg_pool  # the preset itself is untouched


def test_model_step_windows_take_every_step_th_frame_and_group_its_actions(tiny_dataset_master):
    from orbitdata import schema as S
    from orbitdata.load import collate_windows, load_windows
    from orbitmodel.data import load_model_windows

    cols = [S.IMAGE, S.STATE, S.ACTION, S.COLLISION]
    frames = load_windows(tiny_dataset_master, context=8, horizon=4, stride=3, columns=cols)
    steps = load_model_windows(tiny_dataset_master, 2, context=4, horizon=2, stride=3, columns=cols)
    assert len(steps) == len(frames) and len(steps.episodes) == len(frames.episodes)
    raw, item = frames[1], steps[1]
    assert torch.equal(item[S.IMAGE], raw[S.IMAGE][::2]) and torch.equal(item[S.STATE], raw[S.STATE][::2])
    assert item[S.ACTION].shape == (6, 16)
    assert torch.equal(item[S.ACTION][2], torch.cat([raw[S.ACTION][4], raw[S.ACTION][5]]))
    assert torch.equal(item[S.COLLISION], raw[S.COLLISION].view(6, 2).any(1))
    batch = collate_windows(steps.__getitems__([0, 1]))  # the batched path gives the same windows
    assert torch.equal(batch[S.ACTION][1], item[S.ACTION]) and torch.equal(batch[S.IMAGE][1], item[S.IMAGE])
    assert (
        load_model_windows(tiny_dataset_master, 1, context=8, horizon=4, stride=3, columns=cols).__class__
        is frames.__class__
    )  # one frame per step: the loader's own dataset


def test_a_run_from_before_presets_carried_their_probe_recipe_resumes(tiny_dataset_master, tmp_path):
    """Its config.json has no preset.probe: --resume must see the same run, and finish it."""
    from orbitmodel.config import Preset

    out = tmp_path / "legacy"
    _train(tiny_dataset_master, out, steps=2, save_every=1)
    config = json.loads((out / "config.json").read_text())
    del config["preset"]["probe"]
    config["preset"]["description"] = "a few thousand parameters, for tests"  # the built-in's earlier wording
    for key in ("val_fraction", "val_seed"):
        del config["preset"]["train"][key]
    del config["validation"]
    (out / "config.json").write_text(json.dumps(config))
    (out / "model.safetensors").unlink()
    preset = get_preset("tiny").with_train(max_steps=2, save_every=1)
    train_world_model(
        Stage1Request(dataset=str(tiny_dataset_master), preset=preset, out=out, device="cpu", resume=True)
    )
    assert (out / "model.safetensors").is_file()
    upgraded = json.loads((out / "config.json").read_text())["preset"]
    assert "probe" in upgraded and Preset.from_dict(upgraded).probe == get_preset("tiny").probe


def flat(train: dict) -> dict:
    """A training config as config.json held it before the ``loop`` field: the loop's settings
    beside the stage's own."""
    return {**{k: v for k, v in train.items() if k != "loop"}, **train["loop"]}


def test_a_run_with_flat_training_configs_reads_back_and_resumes(tiny_dataset_master, tmp_path):
    """A config.json written before the loop settings were nested (runs on disk and on the Hub):
    it reads as the same run, --resume continues it, and it is rewritten in the nested shape."""
    from orbitmodel.runs import read_run_config

    out = tmp_path / "flat"
    _train(tiny_dataset_master, out, steps=2, save_every=1)
    nested = json.loads((out / "config.json").read_text())
    old = json.loads(json.dumps(nested))
    old["preset"]["train"] = flat(old["preset"]["train"])
    old["preset"]["probe"]["train"] = flat(old["preset"]["probe"]["train"])
    assert old["preset"]["train"]["max_steps"] == 2 and "loop" not in old["preset"]["probe"]["train"]
    (out / "config.json").write_text(json.dumps(old))
    preset = get_preset("tiny").with_train(max_steps=2, save_every=1)
    assert read_run_config(out).preset == preset
    (out / "model.safetensors").unlink()
    train_world_model(
        Stage1Request(dataset=str(tiny_dataset_master), preset=preset, out=out, device="cpu", resume=True)
    )
    assert (out / "model.safetensors").is_file()
    assert json.loads((out / "config.json").read_text()) == nested
