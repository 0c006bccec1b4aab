"""Table I as the paper computes it (issue 37), on a tiny run stepping 2 frames whose probe is
trained as the flown one (every frame of a step, reading latents and thrusts, increment loss),
with every variant beside it: each row recomputed outside ``eval probe``, the thrust-only probe
blind to latents, the latent-only probe chosen on validation, missing rows left out with a note."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitmodel.cli.app import app

runner = CliRunner()
STEP = 2  # frames per world-model step
HORIZONS = (2, 4)
ROWS = ("paper_probe", "latent_probe", "thrust_probe", "thrust_only", "physics", "constant_velocity")
QUANTITIES = ("position", "velocity", "rotation", "angular_velocity", "fuel")
CANDIDATES = ("latent_probe-change-frames-inc", "latent_probe-z-steps-noinc")


def invoke(*args: str):
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


def eval_args(run, data, *more):
    horizons = [x for h in HORIZONS for x in ("--horizon", h)]
    return ("eval", "probe", run, data, *horizons, "--no-figures", *more)


@pytest.fixture(scope="module")
def run(tiny_dataset_master, tmp_path_factory):
    """The run with its probes, the latent_probe chosen on validation and Table I on the test split
    (``RUN/eval``; the validation one in ``RUN/eval-val``; the CLI's output in ``RUN/printed.txt``)."""
    from orbitmodel.config import get_preset
    from orbitmodel.train.stage1 import Stage1Request, train_world_model

    run, data = tmp_path_factory.mktemp("table1") / "wm", str(tiny_dataset_master)
    preset = get_preset("tiny").with_model(frame_step=STEP).with_train(max_steps=30, lr=1e-2, val_fraction=0.5)
    train_world_model(Stage1Request(dataset=data, device="cpu", out=run, preset=preset))
    flown = ("--per-frame", "--inputs", "latent+change+thrust", "--increment-weight", "100")
    invoke("probe", run, data, "--device", "cpu", "--epochs", "20", "--lr", "0.01", *flown)
    for variant in ("paper_probe", "thrust_only", *CANDIDATES):
        invoke("probe", run, data, "--device", "cpu", "--variant", variant)
    invoke(*eval_args(run, data, "--split", "val", "--windows", "1", "--out", run / "eval-val"))
    (run / "printed.txt").write_text(invoke(*eval_args(run, data, "--windows", "2")).output)
    return run


def test_the_table_has_every_row_at_both_histories(run):
    """When every probe is trained: the six rows at the planner's history (2) and the model's (4),
    each cell with the MAE over frames 1..h and the error at h; the thrust-only row is the same at
    both (it reads no latent); the run's probe agrees with probe_table.json, the table the model
    card reads, at the model's history."""
    table = json.loads((run / "eval" / "table1.json").read_text())
    assert table["histories"] == [2, 4] and table["horizons"] == list(HORIZONS) and table["missing"] == {}
    for history in ("2", "4"):
        t = table["by_history"][history]["table"]
        assert set(t) == set(ROWS)
        for row in ROWS:
            for q in QUANTITIES:
                for h in HORIZONS:
                    assert set(t[row][q][f"h{h}"]) == {"mean", "std", "at_h", "at_h_std"}
    two, four = (table["by_history"][h]["table"] for h in ("2", "4"))
    assert two["thrust_only"] == four["thrust_only"] and two["physics"] == four["physics"]
    legacy = json.loads((run / "eval" / "probe_table.json").read_text())
    assert legacy["history"] == 4
    for q in QUANTITIES:
        assert legacy["table"]["probe"][q]["h4"]["mean"] == pytest.approx(
            four["thrust_probe"][q]["h4"]["mean"], rel=1e-6
        )
    printed = (run / "printed.txt").read_text()
    header = "| quantity | h | paper | " + " | ".join(ROWS) + " |"
    assert printed.count(header) == 2 and "seeing 2 latents per imagined step (as the planner flies)" in printed
    assert printed.count("\n| position (m) | 2 | - | ") == 2 and "Left out" not in printed


def test_every_row_agrees_with_an_independent_recomputation(run, tiny_dataset_master):
    """The windows Table I names, read straight from the Parquet shards: the probes fed the model's
    latents here; constant velocity by hand (world velocity and body rates held, R_k = R_0
    exp(k w dt)); the rigid-body model from the true state with the logged thrusts, which
    reproduces the logged states (so the thrusts line up with their frames); every error, the MAE
    over frames 1..h and the error at h, in numpy."""
    import cv2
    import pyarrow.parquet as pq

    from orbitdata.load import read_meta
    from orbitdata.state import rot6d_to_matrix, so3_exp, so3_log
    from orbitmodel import WorldModel
    from orbitmodel.plan.dynamics import RigidBodyDynamics
    from orbitmodel.probe.model import PhysicsProbe

    table = json.loads((run / "eval" / "table1.json").read_text())
    model = WorldModel.from_pretrained(run)
    variants = {r: r for r in ("paper_probe", "thrust_only")} | {"latent_probe": table["latent_probe"]["chosen"]}
    probes = {r: PhysicsProbe.from_pretrained(run, variant=v) for r, v in variants.items()}
    probes["thrust_probe"] = PhysicsProbe.from_pretrained(run)
    sim = read_meta(tiny_dataset_master)[0].generation_config().sim
    rigid = RigidBodyDynamics(sim, substeps=sim.substeps)
    shards = sorted((tiny_dataset_master / "data").glob("test-*.parquet"))
    steps = pq.read_table(shards).to_pylist()
    m, n, s, dt = table["context"], max(HORIZONS), STEP, S.DT
    errors = {h: {r: {q: [] for q in QUANTITIES} for r in ROWS} for h in table["histories"]}
    for episode, first in zip(table["episodes"], table["first_frames"]):
        rows = sorted(
            (r for r in steps if r[S.EPISODE_INDEX] == episode and first <= r[S.FRAME_INDEX] < first + m + n),
            key=lambda r: r[S.FRAME_INDEX],
        )
        assert len(rows) == m + n
        decode = [cv2.imdecode(np.frombuffer(r[S.IMAGE]["bytes"], np.uint8), cv2.IMREAD_COLOR) for r in rows[:m]]
        images = np.stack([cv2.cvtColor(x, cv2.COLOR_BGR2RGB) for x in decode])  # (m, H, W, 3)
        states = np.array([r[S.STATE] for r in rows], np.float64)  # (m + n, 16)
        actions = np.array([r[S.ACTION] for r in rows], np.float32)  # (m + n, 8)
        true, x0 = states[m:], states[m - 1]
        R0, w0 = rot6d_to_matrix(x0[6:12]), x0[12:15]
        u0 = R0 @ x0[3:6]  # m/s, world frame
        R = np.stack([R0 @ so3_exp(w0 * k * dt) for k in range(1, n + 1)])  # (n, 3, 3)
        coast = np.concatenate(
            [
                x0[0:3] + np.arange(1, n + 1)[:, None] * dt * u0,
                np.einsum("kji,j->ki", R, u0),  # R_k^T u0: body frame
                R[:, :, :2].reshape(n, 6),  # rot6d: the first two columns, row by row
                np.tile(w0, (n, 1)),
                np.full((n, 1), x0[15]),
            ],
            1,
        )
        physics = rigid.rollout(
            torch.tensor(x0[None], dtype=torch.float32), torch.from_numpy(actions[None, m - 1 : -1])
        )
        preds = {"constant_velocity": coast, "physics": physics[0].double().numpy()}
        assert np.abs(preds["physics"] - true).max() < 1e-4  # MuJoCo's scheme from the true state: the logged states
        with torch.no_grad():
            z = model.encode(
                torch.from_numpy(images[::s]).permute(0, 3, 1, 2)[None], torch.tensor(states[None, :m:s]).float()
            )
            grouped = torch.from_numpy(actions[: m - 1 + n]).reshape(1, (m - 1 + n) // s, 8 * s)  # s thrusts a step
            future, state0 = grouped[:, (m - 1) // s :], torch.tensor(x0[None]).float()
            for history in table["histories"]:
                z_future = model.rollout(z, grouped, history=history)
                for row, probe in probes.items():
                    preds[row] = probe.per_frame(z_future, state0, z[:, -1], s, future)[0].double().numpy()
                for row, pred in preds.items():
                    rel = np.swapaxes(rot6d_to_matrix(true[:, 6:12]), -1, -2) @ rot6d_to_matrix(pred[:, 6:12])
                    e = errors[history][row]
                    e["position"].append(np.abs(pred[:, 0:3] - true[:, 0:3]).mean(-1))
                    e["velocity"].append(np.abs(pred[:, 3:6] - true[:, 3:6]).mean(-1))
                    e["rotation"].append(np.linalg.norm(so3_log(rel), axis=-1))
                    e["angular_velocity"].append(np.abs(pred[:, 12:15] - true[:, 12:15]).mean(-1))
                    e["fuel"].append(np.abs(pred[:, 15] - true[:, 15]))
    for history, per_row in errors.items():
        t = table["by_history"][str(history)]["table"]
        for row, per_q in per_row.items():
            for q, per_window in per_q.items():
                e = np.stack(per_window)  # (windows, n)
                for h in HORIZONS:
                    cell = t[row][q][f"h{h}"]
                    where = (history, row, q, h)
                    assert cell["mean"] == pytest.approx(e[:, :h].mean(1).mean(), rel=1e-4, abs=1e-6), where
                    assert cell["std"] == pytest.approx(e[:, :h].mean(1).std(), rel=1e-3, abs=1e-6), where
                    assert cell["at_h"] == pytest.approx(e[:, h - 1].mean(), rel=1e-4, abs=1e-6), where
    assert not np.allclose(errors[2]["thrust_probe"]["position"], errors[2]["thrust_only"]["position"])


def test_the_retrained_thrust_only_probe_receives_no_latent(run):
    """The thrust_only probe as trained: random latents (and none of the context) give the same
    states; the thrusts move them."""
    from orbitmodel.probe.model import PhysicsProbe

    probe = PhysicsProbe.from_pretrained(run, variant="thrust_only")
    assert probe.config.inputs == "thrust" and not any(k.startswith("increments.net.") for k in probe.state_dict())
    g = torch.Generator().manual_seed(0)
    D, steps = probe.config.latent_dim, 2
    state0, thrusts = torch.zeros(3, 16), torch.rand(3, steps, 8 * STEP, generator=g) * 0.3
    state0[:, 6], state0[:, 9], state0[:, 15] = 1.0, 1.0, 0.9  # R = I, a full tank
    out = [
        probe.per_frame(
            torch.randn(3, steps, D, generator=g) * 5, state0, torch.randn(3, D, generator=g), STEP, thrusts
        )
        for _ in range(3)
    ]
    assert out[0].shape == (3, steps * STEP, 16)
    assert torch.equal(out[0], out[1]) and torch.equal(out[0], out[2])
    assert not torch.allclose(out[0], probe.per_frame(torch.zeros(3, steps, D), state0, None, STEP, thrusts.flip(1)))


def test_the_latent_probe_is_chosen_on_validation(run):
    """eval probe --split val scores the trained candidates (most cells at or below the reference,
    here constant velocity: the paper has no h = 2 or 4, then the smallest geometric mean of the
    ratios), records the best in the run, and the test table's latent_probe row reads it."""
    val = json.loads((run / "eval-val" / "table1.json").read_text())
    assert val["split"] == "val" and set(val["latent_probe"]["scores"]) == set(CANDIDATES)
    score = {}
    for c in CANDIDATES:
        met, logs = 0, []
        for entry in val["by_history"].values():
            t = entry["table"]
            for q in QUANTITIES:
                for h in HORIZONS:
                    mine, ref = t[c][q][f"h{h}"]["mean"], t["constant_velocity"][q][f"h{h}"]["mean"]
                    met += mine <= ref
                    logs.append(np.log(mine / ref))
        score[c] = (met, -np.mean(logs))
    best = max(CANDIDATES, key=score.get)
    choice = json.loads((run / "latent_probe.json").read_text())
    assert val["latent_probe"]["chosen"] == choice["chosen"] == best and choice["split"] == "val"
    assert val["by_history"]["2"]["table"]["latent_probe"] == val["by_history"]["2"]["table"][best]
    test = json.loads((run / "eval" / "table1.json").read_text())
    assert test["latent_probe"]["chosen"] == best and test["probes"]["latent_probe"]["folder"] == f"probe-{best}"
    assert not set(CANDIDATES) & set(test["by_history"]["2"]["table"])  # the test split only reports the choice


def test_a_missing_probe_row_is_left_out_with_its_note(run, tiny_dataset_master, tmp_path):
    """Without the paper's probe and without a choice, Table I has the other rows and one line
    per missing row naming the command that makes it; a choice made before its candidate was
    trained again is not followed."""
    data = str(tiny_dataset_master)
    bare = tmp_path / "bare"
    shutil.copytree(run, bare, ignore=shutil.ignore_patterns("probe-paper_probe", "latent_probe.json", "eval*"))
    res = invoke(*eval_args(bare, data, "--windows", "2"))
    table = json.loads((bare / "eval" / "table1.json").read_text())
    rows = {"thrust_probe", "thrust_only", "physics", "constant_velocity"}
    assert set(table["rows"]) == rows and all(set(e["table"]) == rows for e in table["by_history"].values())
    assert set(table["missing"]) == {"paper_probe", "latent_probe"}
    assert f"`orbitmodel probe {bare} DATASET --variant paper_probe`" in table["missing"]["paper_probe"]
    assert f"`orbitmodel eval probe {bare} DATASET --split val`" in table["missing"]["latent_probe"]
    assert "Left out, `paper_probe`: " in res.output and "Left out, `latent_probe`: " in res.output
    assert "| quantity | h | paper | thrust_probe | thrust_only | physics | constant_velocity |" in res.output
    choice = json.loads((run / "latent_probe.json").read_text())
    (bare / "latent_probe.json").write_text(json.dumps({**choice, "probe": "retrained"}))
    invoke(*eval_args(bare, data, "--windows", "2"))
    table = json.loads((bare / "eval" / "table1.json").read_text())
    assert "choose again" in table["missing"]["latent_probe"] and "latent_probe" not in table["rows"]


def test_a_variant_keeps_what_makes_it(run, tiny_dataset_master, tmp_path):
    """A variant is the run's probe as trained with only what its name says changed (the paper's
    reads z_k, integrates as upstream, no increment loss; the thrust-only one reads thrusts alone);
    a flag that would undo it, or a variant of the state-only reference, is one line and exit 2."""
    flown = json.loads((run / "probe" / "config.json").read_text())
    for variant, changed in (
        ("paper_probe", {"inputs": "latent", "integrator": "upstream", "increment_weight": 0.0, "action_dim": 0}),
        ("thrust_only", {"inputs": "thrust"}),
        (
            "latent_probe-z-steps-noinc",
            {"inputs": "latent", "substeps": 1, "dt": S.DT * STEP, "increment_weight": 0.0, "action_dim": 0},
        ),
    ):
        config = json.loads((run / f"probe-{variant}" / "config.json").read_text())
        assert config["variant"] == variant
        for part in ("probe", "train"):
            for key, value in flown[part].items():
                assert config[part][key] == changed.get(key, value), (variant, part, key)
    data = str(tiny_dataset_master)
    for args, message in (
        (("--variant", "paper_probe", "--inputs", "latent+change"), "--inputs: the paper_probe variant sets inputs"),
        (("--variant", "thrust_only", "--state-only"), "--variant thrust_only: the state-only reference"),
        (("--variant", "latent_probe-z-frames-inc", "--increment-weight", "0"), "--increment-weight"),
    ):
        res = runner.invoke(app, ["probe", str(run), data, *args])
        assert res.exit_code == 2 and message in res.output and "Traceback" not in res.output, res.output
        assert len(res.output.strip().splitlines()) == 1, res.output
