"""Stage II on tiny data: the probe trains on a frozen world model, resumes, is evaluated into
the Table I layout, and bad input gives one line and exit 2."""

import json
import re
import shutil
from dataclasses import replace

import pytest
import torch
from safetensors.torch import load_file
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitdata.load import load_windows
from orbitmodel.cli.app import app
from orbitmodel.config import get_preset
from orbitmodel.probe.cache import CACHE_FILE, LAST, LATENT
from orbitmodel.probe.config import ProbeConfig
from orbitmodel.probe.evaluate import PAPER, QUANTITIES, ROWS, TABLE_JSON, TABLE_MD
from orbitmodel.probe.model import PhysicsProbe
from orbitmodel.probe.train import LatentObjective, ProbeJob, ProbeRequest, load_stage1, train_probe
from orbitmodel.runs import RunDir, RunError
from orbitmodel.train.loop import fit

runner = CliRunner()


@pytest.fixture
def run(tiny_run, tmp_path):
    dst = tmp_path / "run"
    shutil.copytree(tiny_run, dst)
    return dst


def request(run, dataset, kind="latent", **changes):
    return ProbeRequest(
        run=run, dataset=str(dataset), recipe=get_preset("tiny").probe.with_changes(**changes), kind=kind, device="cpu"
    )


def test_the_world_model_stays_frozen_bit_for_bit(run, tiny_dataset_master):
    """No cache: the world model runs on every batch, and ends exactly as it started
    (weights and BatchNorm statistics), even when the objective is put in train mode."""
    world_model = load_stage1(run)
    before = {k: v.clone() for k, v in world_model.state_dict().items()}
    t = get_preset("tiny").probe.train.with_changes(cache_windows=0, max_steps=4)
    probe = PhysicsProbe(ProbeConfig(latent_dim=32, hidden=32))
    module = LatentObjective(world_model, probe, t).train()
    windows = load_windows(
        tiny_dataset_master,
        context=t.context,
        horizon=t.horizon,
        stride=t.window_stride,
        columns=[S.IMAGE, S.STATE, S.ACTION],
    )
    out = run / "probe"
    RunDir(out).start({"stage": "probe"}, resume=False, overwrite=False)
    fit(ProbeJob(module, probe, "latent", t.context), windows, t.loop, RunDir(out), torch.device("cpu"))
    assert not world_model.training and all(not p.requires_grad for p in world_model.parameters())
    after = world_model.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before)
    assert any(p.abs().sum() > 0 for p in probe.increments.net[-1].parameters())  # the probe did train


def test_probe_trains_and_the_loss_falls(run, tiny_dataset_master):
    result = train_probe(request(run, tiny_dataset_master, epochs=12))
    assert result.steps == 12 * (32 // 4)
    batch = load_file(run / "probe" / CACHE_FILE)  # the imagined latents of the 32 training windows
    world_model = load_stage1(run)
    t = get_preset("tiny").probe.train

    def loss(probe):
        with torch.no_grad():
            return float(
                LatentObjective(world_model, probe, t)(
                    batch[S.STATE], batch[S.ACTION], z_future=batch[LATENT], z_last=batch[LAST]
                )[0]
            )

    trained = PhysicsProbe.from_pretrained(run)
    untrained = PhysicsProbe(trained.config)  # zero increments: coasting
    assert loss(trained) < 0.8 * loss(untrained)
    assert trained.increments.scale.ne(1).all()  # output units from the data


def test_a_per_frame_probe_is_scored_on_every_frame_after_the_context(tiny_dataset_master):
    """At frame step s, the per-frame probe's loss compares its n s states with the window's states
    of frames (m-1) s + 1 .. (m-1+n) s; an untrained (coasting) probe's loss is recomputed here."""
    from orbitmodel.data import FRAME_STATES, load_model_windows
    from orbitmodel.model.world_model import WorldModel
    from orbitmodel.probe.baselines import constant_velocity
    from orbitmodel.probe.train import probe_config, state_loss

    s, preset = 2, get_preset("tiny").with_model(frame_step=2)
    t = preset.probe.train  # context 4, horizon 4 model steps
    windows = load_model_windows(
        str(tiny_dataset_master),
        s,
        split="train",
        context=t.context,
        horizon=t.horizon,
        columns=[S.IMAGE, S.STATE, S.ACTION],
        frame_states=True,
    )
    batch = windows.__getitems__([0, 5, 9]).stacked
    assert batch[FRAME_STATES].shape[1] == (t.context + t.horizon) * s
    assert torch.equal(batch[FRAME_STATES][:, ::s], batch[S.STATE])  # a model step's state is its first frame's
    config = probe_config(preset.probe.with_changes(per_frame=True), "latent", preset.model.latent_dim, s)
    assert (config.substeps, config.dt) == (s, S.DT)
    objective = LatentObjective(WorldModel(preset.model), PhysicsProbe(config), t)
    with torch.no_grad():
        got = objective(
            batch[S.STATE], batch[S.ACTION], images=batch[S.IMAGE][:, : t.context], frame_states=batch[FRAME_STATES]
        )[0]
    start = (t.context - 1) * s
    truth = batch[FRAME_STATES][:, start + 1 : start + 1 + t.horizon * s]
    expected = state_loss(constant_velocity(batch[S.STATE][:, t.context - 1], t.horizon * s, S.DT), truth, t.weights)[0]
    assert torch.allclose(got, expected)


def test_the_increment_loss_scores_each_frames_change_in_output_units(tiny_dataset_master):
    """increment_weight w adds w x MSE((predicted - true increments) / scale), the true increments
    taken between the window's consecutive frame states from the last context frame on."""
    import dataclasses

    from orbitmodel.data import FRAME_STATES, load_model_windows
    from orbitmodel.model.world_model import WorldModel
    from orbitmodel.probe.integrator import increments_of
    from orbitmodel.probe.train import probe_config

    s, preset = 2, get_preset("tiny").with_model(frame_step=2)
    t = preset.probe.train
    windows = load_model_windows(
        str(tiny_dataset_master),
        s,
        split="train",
        context=t.context,
        horizon=t.horizon,
        columns=[S.IMAGE, S.STATE, S.ACTION],
        frame_states=True,
    )
    batch = windows.__getitems__([0, 5]).stacked
    recipe = preset.probe.with_changes(per_frame=True, inputs="latent+change+thrust")
    probe = PhysicsProbe(probe_config(recipe, "latent", preset.model.latent_dim, s))
    torch.nn.init.normal_(probe.increments.thrust_net[-1].weight, generator=torch.Generator().manual_seed(0))
    probe.increments.set_scale(torch.linspace(0.5, 2.0, 10))
    world_model = WorldModel(preset.model)
    args = dict(images=batch[S.IMAGE][:, : t.context], frame_states=batch[FRAME_STATES])
    with torch.no_grad():
        plain, _ = LatentObjective(world_model, probe, t)(batch[S.STATE], batch[S.ACTION], **args)
        both, parts = LatentObjective(world_model, probe, dataclasses.replace(t, increment_weight=3.0))(
            batch[S.STATE], batch[S.ACTION], **args
        )
        z = world_model.encode(batch[S.IMAGE][:, : t.context], batch[S.STATE][:, : t.context])
        z_future = world_model.rollout(z, batch[S.ACTION][:, :-1])
        inc = probe.step_increments(z_future, z[:, -1], batch[S.ACTION][:, t.context - 1 : -1])
    start = (t.context - 1) * s
    true = increments_of(batch[FRAME_STATES][:, start : start + 1 + t.horizon * s], S.DT, coasting=True)
    expected = ((inc - true) / probe.increments.scale).pow(2).mean()
    assert torch.allclose(parts["increments"], expected) and torch.allclose(both, plain + 3 * expected)


def test_a_probe_run_from_before_per_frame_heads_resumes(run, tiny_dataset_master):
    """A probe config.json without substeps, action_dim and increment_weight (written before they
    existed) resumes: it reads as the defaults it trained with."""
    train_probe(request(run, tiny_dataset_master, epochs=1))
    path = run / "probe" / "config.json"
    config = json.loads(path.read_text())
    assert config["probe"]["action_dim"] == 0  # a probe that reads no thrusts records none
    del config["probe"]["substeps"], config["probe"]["action_dim"], config["train"]["increment_weight"]
    path.write_text(json.dumps(config))
    (run / "probe" / "model.safetensors").unlink()  # so the resume has the run to finish
    req = request(run, tiny_dataset_master, epochs=1)
    train_probe(ProbeRequest(run=req.run, dataset=req.dataset, recipe=req.recipe, device="cpu", resume=True))
    assert (run / "probe" / "model.safetensors").is_file()
    again = json.loads(path.read_text())  # rewritten with the defaults it trained with
    assert again["probe"]["substeps"] == 1 and again["probe"]["action_dim"] == 0
    assert again["train"]["increment_weight"] == 0


def test_a_probe_run_with_a_flat_training_config_resumes_as_the_same_run(run, tiny_dataset_master):
    """A probe config.json from before the loop settings were nested (its ``train`` flat) is the
    same run: --resume continues it and rewrites it nested; another setting is still another run."""
    train_probe(request(run, tiny_dataset_master, epochs=1))
    path = run / "probe" / "config.json"
    nested = json.loads(path.read_text())
    train = nested["train"]
    path.write_text(
        json.dumps({**nested, "train": {**{k: v for k, v in train.items() if k != "loop"}, **train["loop"]}})
    )
    (run / "probe" / "model.safetensors").unlink()
    with pytest.raises(RunError, match=r"another config \(differs in: train.loop.epochs: 1 -> 2\)"):
        train_probe(replace(request(run, tiny_dataset_master, epochs=2), resume=True))
    train_probe(replace(request(run, tiny_dataset_master, epochs=1), resume=True))
    assert (run / "probe" / "model.safetensors").is_file() and json.loads(path.read_text()) == nested


class Interrupt(Exception):
    pass


def test_resume_continues_exactly(run, tiny_dataset_master, tmp_path):
    other = tmp_path / "other"
    shutil.copytree(run, other)
    train_probe(request(run, tiny_dataset_master))

    def stop(record):
        if record["step"] == 5:
            raise Interrupt  # after the checkpoint of step 4

    with pytest.raises(Interrupt):
        train_probe(request(other, tiny_dataset_master), on_log=stop)
    resumed = ProbeRequest(**{**request(other, tiny_dataset_master).__dict__, "resume": True})
    train_probe(resumed)  # reads the cached latents back
    straight, again = PhysicsProbe.from_pretrained(run).state_dict(), PhysicsProbe.from_pretrained(other).state_dict()
    assert all(torch.equal(straight[k], again[k]) for k in straight)


def test_a_probe_cut_before_its_first_checkpoint_starts_again_resumed_or_not(run, tiny_dataset_master, tmp_path):
    """Its folder holds the config and nothing trained: a rerun, with --resume or without, trains it
    from the start, its increment scale set as a fresh run sets it."""
    copies = {name: tmp_path / name for name in ("again", "resumed")}
    for copy in copies.values():
        shutil.copytree(run, copy)
    train_probe(request(run, tiny_dataset_master))
    straight = PhysicsProbe.from_pretrained(run).state_dict()

    def stop(record):
        if record["step"] == 1:
            raise Interrupt  # before the first checkpoint, at step 2

    for name, copy in copies.items():
        with pytest.raises(Interrupt):
            train_probe(request(copy, tiny_dataset_master), on_log=stop)
        assert not (copy / "probe" / "checkpoints").exists()
        train_probe(ProbeRequest(**{**request(copy, tiny_dataset_master).__dict__, "resume": name == "resumed"}))
        again = PhysicsProbe.from_pretrained(copy).state_dict()
        assert all(torch.equal(straight[k], again[k]) for k in straight), name


def test_eval_writes_the_table_and_figures(run, tiny_dataset_master, tmp_path):
    for flag in ([], ["--state-only"]):
        res = runner.invoke(app, ["probe", str(run), str(tiny_dataset_master), "--device", "cpu", *flag])
        assert res.exit_code == 0, res.output
        # the time it ends with is the command's, imagining the windows and all, beside the training's
        assert re.search(
            r"steps in [0-9.]+ min \(.*\); [0-9.]+ min in all, (imagining|reading) the windows included", res.output
        )
    config = PhysicsProbe.from_pretrained(run).config
    assert (config.integrator, config.inputs) == ("coasting", "latent+change")  # the defaults
    out = tmp_path / "eval"
    res = runner.invoke(
        app,
        [
            "eval",
            "probe",
            str(run),
            str(tiny_dataset_master),
            "--windows",
            "2",
            "--horizon",
            "25",
            "--horizon",
            "50",
            "--out",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    result = json.loads((out / TABLE_JSON).read_text())
    for row in ROWS:
        for q in QUANTITIES:
            for h in (25, 50):
                cell = result["table"][row][q][f"h{h}"]
                assert cell["mean"] >= 0 and cell["std"] >= 0
            assert len(result["table"][row][q]["per_step"]) == 50
    table = (out / TABLE_MD).read_text()
    assert table.count("\n| ") == 1 + 2 * len(QUANTITIES)  # header + one line per quantity and horizon
    assert f"{PAPER[25]['position']:.4f}" in table and f"{PAPER[50]['fuel']:.4f}" in table
    assert (out / "probe_fig5_states.png").stat().st_size > 0 and (out / "probe_fig5_3d.png").stat().st_size > 0


def one_line_error(res, message):
    assert res.exit_code == 2, res.output
    assert message in res.output and "Traceback" not in res.output
    # datasets' bar while it caches a split on its first load (whichever test loads it first) is not the error
    lines = [line for line in res.output.strip().splitlines() if not line.startswith("Generating ")]
    assert len(lines) == 1, res.output


def test_clear_errors(run, tiny_dataset_master, tmp_path):
    data = str(tiny_dataset_master)
    one_line_error(runner.invoke(app, ["probe", str(tmp_path / "nothing"), data]), "not an orbitmodel run")
    one_line_error(runner.invoke(app, ["eval", "probe", str(run), data]), "no physics probe")
    untrained = tmp_path / "untrained"
    shutil.copytree(run, untrained)
    (untrained / "model.safetensors").unlink()
    shutil.rmtree(untrained / "checkpoints")
    one_line_error(runner.invoke(app, ["probe", str(untrained), data]), "has no weights")
    other_size = tmp_path / "other_size"
    shutil.copytree(run, other_size)
    config = json.loads((other_size / "config.json").read_text())
    config["preset"]["model"]["image_size"] = 32
    (other_size / "config.json").write_text(json.dumps(config))
    one_line_error(runner.invoke(app, ["probe", str(other_size), data]), "holds 64 px")
    one_line_error(
        runner.invoke(app, ["probe", str(run), data, "--state-only", "--increment-weight", "1"]), "--increment-weight"
    )
    for bad in ("1,1,1", "1,1,1,1,x", "1,1,1,1,-1", "nan,1,1,1,1", "1,inf,1,1,1"):
        one_line_error(runner.invoke(app, ["probe", str(run), data, "--loss-weights", bad]), "--loss-weights")
    assert runner.invoke(app, ["probe", str(run), data, "--max-steps", "1"]).exit_code == 0
    one_line_error(
        runner.invoke(app, ["eval", "probe", str(run), data, "--windows", "50", "--horizon", "5", "--no-figures"]),
        "test episodes",
    )
    too_long = runner.invoke(
        app, ["eval", "probe", str(run), data, "--windows", "2", "--horizon", "5000", "--no-figures"]
    )
    one_line_error(too_long, "--horizon 5000:")
    assert "give --horizon" in too_long.output and "pad=True" not in too_long.output, too_long.output


def test_the_probe_takes_the_recipe_its_run_records_not_its_presets_name(run, tiny_dataset_master, tmp_path):
    """A run whose preset has its own name and recipe: `orbitmodel probe` trains what config.json says."""
    custom = tmp_path / "custom"
    shutil.copytree(run, custom, ignore=shutil.ignore_patterns("probe*"))
    config = json.loads((custom / "config.json").read_text())
    config["preset"]["name"] = "mine"
    config["preset"]["probe"].update(inputs="latent", integrator="upstream", hidden=24)
    config["preset"]["probe"]["train"].update(weights=[1, 2, 3, 4, 5])
    config["preset"]["probe"]["train"]["loop"].update(epochs=1)
    (custom / "config.json").write_text(json.dumps(config))
    res = runner.invoke(app, ["probe", str(custom), str(tiny_dataset_master), "--device", "cpu"])
    assert res.exit_code == 0, res.output
    probe = json.loads((custom / "probe" / "config.json").read_text())
    assert (probe["probe"]["inputs"], probe["probe"]["integrator"], probe["probe"]["hidden"]) == (
        "latent",
        "upstream",
        24,
    )
    assert probe["train"]["loop"]["epochs"] == 1 and probe["train"]["weights"] == [1, 2, 3, 4, 5]
    res = runner.invoke(
        app,
        [
            "probe",
            str(custom),
            str(tiny_dataset_master),
            "--device",
            "cpu",
            "--overwrite",
            "--inputs",
            "latent+change",
            "--epochs",
            "2",
        ],
    )  # flags change single settings
    probe = json.loads((custom / "probe" / "config.json").read_text())
    assert res.exit_code == 0 and probe["probe"]["inputs"] == "latent+change" and probe["train"]["loop"]["epochs"] == 2


@pytest.mark.parametrize("frame_step", [1, 2])
def test_table_one_agrees_with_an_independent_per_frame_computation(tiny_dataset_master, tmp_path, frame_step):
    """eval probe, checked from outside: the windows it names (episode, first frame) are read
    straight from the Parquet shards, encoded, rolled out at the planner's history and probed here,
    and the errors recomputed in numpy at every frame (the attitude as |log(R_true^T R_pred)|); the
    same Table I. At frame step 2 (the flown configuration's kind) the world model sees every other
    frame and a per-frame probe reading each step's thrusts predicts both frames of each step."""
    import cv2
    import numpy as np
    import pyarrow.parquet as pq

    from orbitdata.state import rot6d_to_matrix, so3_log
    from orbitmodel import WorldModel
    from orbitmodel.train.stage1 import Stage1Request, train_world_model

    run = tmp_path / "wm"  # trained long enough that its predictor, and so the history, matters
    s = frame_step
    train_world_model(
        Stage1Request(
            dataset=str(tiny_dataset_master),
            device="cpu",
            out=run,
            preset=get_preset("tiny").with_model(frame_step=s).with_train(max_steps=30, lr=1e-2),
        )
    )
    # a probe whose output the latents move
    flown_kind = {"per_frame": True, "inputs": "latent+change+thrust"} if s > 1 else {}
    train_probe(request(run, tiny_dataset_master, epochs=20, lr=1e-2, **flown_kind))
    res = runner.invoke(
        app,
        [
            "eval",
            "probe",
            str(run),
            str(tiny_dataset_master),
            "--windows",
            "2",
            "--horizon",
            "2",
            "--horizon",
            "4",
            "--history",
            "2",
            "--no-figures",
        ],
    )
    assert res.exit_code == 0, res.output
    table = json.loads((run / "eval" / TABLE_JSON).read_text())
    assert table["history"] == 2 and "seeing 2 latents" in res.output and table["per_frame"] == (s > 1)
    model, probe = WorldModel.from_pretrained(run), PhysicsProbe.from_pretrained(run)
    steps = pq.read_table(sorted((tiny_dataset_master / "data").glob("test-*.parquet"))).to_pylist()
    m, n = table["context"], max(table["horizons"])
    errors = {q: [] for q in ("position", "velocity", "rotation", "angular_velocity", "fuel")}
    for episode, first in zip(table["episodes"], table["first_frames"]):
        rows = sorted(
            (r for r in steps if r[S.EPISODE_INDEX] == episode and first <= r[S.FRAME_INDEX] < first + m + n),
            key=lambda r: r[S.FRAME_INDEX],
        )
        assert len(rows) == m + n
        images = np.stack(
            [
                cv2.cvtColor(
                    cv2.imdecode(np.frombuffer(r[S.IMAGE]["bytes"], np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB
                )
                for r in rows[:m]
            ]
        )  # (m, H, W, 3)
        states = np.array([r[S.STATE] for r in rows], np.float32)  # (m + n, 16)
        actions = np.array([r[S.ACTION] for r in rows], np.float32)
        with torch.no_grad():
            z = model.encode(
                torch.from_numpy(images[::s]).permute(0, 3, 1, 2)[None], torch.from_numpy(states[None, :m:s])
            )  # every s-th frame, the last at m - 1
            grouped = torch.from_numpy(actions[: m - 1 + n]).reshape(1, (m - 1 + n) // s, 8 * s)  # s thrusts a step
            z_future = model.rollout(z, grouped, history=2)
            future = grouped[:, (m - 1) // s :] if s > 1 else None  # the thrusts of each imagined step
            pred = (
                probe(z_future, torch.from_numpy(states[None, m - 1]), z[:, -1], future)[0].double().numpy()
            )  # (n, 16)
        assert pred.shape == (n, 16)  # the probe itself gives every frame
        true = states[m:].astype(np.float64)
        rel = np.swapaxes(rot6d_to_matrix(true[:, 6:12]), -1, -2) @ rot6d_to_matrix(pred[:, 6:12])
        errors["position"].append(np.abs(pred[:, 0:3] - true[:, 0:3]).mean(-1))
        errors["velocity"].append(np.abs(pred[:, 3:6] - true[:, 3:6]).mean(-1))
        errors["rotation"].append(np.linalg.norm(so3_log(rel), axis=-1))
        errors["angular_velocity"].append(np.abs(pred[:, 12:15] - true[:, 12:15]).mean(-1))
        errors["fuel"].append(np.abs(pred[:, 15] - true[:, 15]))
    for q, per_window in errors.items():
        for h in table["horizons"]:
            mine = float(np.mean([e[:h].mean() for e in per_window]))
            assert mine == pytest.approx(table["table"]["probe"][q][f"h{h}"]["mean"], rel=1e-4, abs=1e-6), (q, h)


def test_calm_windows_are_those_whose_every_frame_stays_under_the_rate(tiny_dataset_master):
    from orbitdata.load import collate_windows
    from orbitmodel.data import calm_windows, load_model_windows
    from orbitmodel.kinematics import W

    windows = load_model_windows(tiny_dataset_master, 2, context=2, horizon=2, stride=1, columns=[S.STATE])
    frames = collate_windows(windows.frames.__getitems__(list(range(len(windows)))))[S.STATE]  # every frame
    peak = frames[..., W].norm(dim=-1).amax(1)  # (N,) the fastest frame of each window
    rate = float(peak.median())
    calm = calm_windows(windows, rate)
    assert calm == [i for i in range(len(windows)) if peak[i] <= rate]
    assert 0 < len(calm) < len(windows)


def test_a_probe_with_a_rate_limit_trains_on_calm_windows_only(run, tiny_dataset_master):
    from orbitmodel.kinematics import W

    def peaks():  # the fastest body rate of each window the probe trained on
        return load_file(run / "probe" / CACHE_FILE)[S.STATE][..., W].norm(dim=-1).amax(1)

    train_probe(request(run, tiny_dataset_master, max_steps=1))
    every = peaks()
    rate = float(every.median())
    train_probe(replace(request(run, tiny_dataset_master, max_steps=1, max_body_rate=rate), overwrite=True))
    calm = peaks()
    assert (every > rate).any() and (calm <= rate).all()
    assert len(calm) >= int((every <= rate).sum())  # as many windows as there are calm ones, up to the cache's size
    config = json.loads((run / "probe" / "config.json").read_text())
    assert config["train"]["max_body_rate"] == rate


def test_the_context_and_rate_flags_and_a_rate_no_window_meets(run, tiny_dataset_master):
    data = str(tiny_dataset_master)
    flags = ["--context", "2", "--max-body-rate", "1000", "--max-steps", "1"]
    assert runner.invoke(app, ["probe", str(run), data, *flags]).exit_code == 0
    train = json.loads((run / "probe" / "config.json").read_text())["train"]
    assert (train["context"], train["max_body_rate"]) == (2, 1000.0)  # the flags land in the probe's record
    one_line_error(
        runner.invoke(app, ["probe", str(run), data, "--max-body-rate", "1e-9", "--overwrite"]), "--max-body-rate 1e-09"
    )
    assert (run / "probe" / "model.safetensors").exists()  # refused before --overwrite removed anything
    one_line_error(
        runner.invoke(app, ["probe", str(run), data, "--max-body-rate", "1", "--cache-windows", "0", "--overwrite"]),
        "cache_windows",
    )


def test_eval_context_sets_the_windows_so_probes_of_other_contexts_share_them(run, tiny_dataset_master, tmp_path):
    """--context N encodes N steps before the horizon whatever context the probe trained with: the
    windows (and so the constant-velocity row) are those of a probe trained with context N."""
    train_probe(request(run, tiny_dataset_master, max_steps=1, context=2))

    def scored(*flags):
        out = tmp_path / ("eval" + "".join(flags))
        args = ["eval", "probe", str(run), str(tiny_dataset_master), "--windows", "2", "--horizon", "5"]
        res = runner.invoke(app, [*args, "--out", str(out), "--no-figures", *flags])
        assert res.exit_code == 0, res.output
        return json.loads((out / TABLE_JSON).read_text())

    own, wider = scored(), scored("--context", "4")
    assert (own["context"], wider["context"]) == (2, 4)  # frames: one model step per frame in the tiny run
    assert own["table"]["probe"] != wider["table"]["probe"]
