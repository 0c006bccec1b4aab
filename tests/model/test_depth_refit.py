"""``orbitmodel depth``: the depth head refitted for the planner, and the planner's choice of head."""

from __future__ import annotations

import json
import shutil

import pytest
import torch
from typer.testing import CliRunner

from orbitmodel.cli.app import app
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import planner_config
from orbitmodel.plan.depth_refit import DepthRefitConfig, load_refit_head, refit_depth_head
from orbitmodel.plan.factory import build_pilot
from orbitmodel.runs import RunError

torch.set_num_threads(1)
runner = CliRunner()
SMALL = ["--frames", "96", "--test-frames", "32", "--epochs", "12"]


@pytest.fixture(scope="module")
def refit_run(tiny_run, tiny_dataset_master, tmp_path_factory):
    """A copy of the tiny run with its depth head refitted through the CLI; (run, CLI output)."""
    run = tmp_path_factory.mktemp("refit") / "tiny"
    shutil.copytree(tiny_run, run)
    res = runner.invoke(app, ["depth", str(run), str(tiny_dataset_master), *SMALL])
    assert res.exit_code == 0, res.output
    return run, res.output


def test_the_refit_writes_its_head_and_the_before_after_table(refit_run, tiny_run):
    run, output = refit_run
    assert "Stage I -> refit" in output and "missed" in output
    result = json.loads((run / "depth" / "eval.json").read_text())
    for name in ("stage1", "refit"):
        assert sum(b["cells"] for b in result[name]["bands"]) == 32 * 256  # every test cell, in one band
    losses = result["epoch_loss"]
    assert len(losses) == 12 and losses[-1] < losses[0]  # the near-weighted loss goes down
    model = WorldModel.from_pretrained(run)
    head = load_refit_head(run, model)
    assert any(
        not torch.equal(a, b) for a, b in zip(head.state_dict().values(), model.depth_head.state_dict().values())
    )
    # The Stage I weights are untouched: the latents (and so the dynamics and the probe) do not move.
    assert (run / "model.safetensors").read_bytes() == (tiny_run / "model.safetensors").read_bytes()


def test_the_refit_is_reproducible_from_its_seed(refit_run, tiny_dataset_master, tmp_path):
    run, _ = refit_run
    again = tmp_path / "again"
    shutil.copytree(run, again)
    cfg = DepthRefitConfig(frames=96, test_frames=32, epochs=12)
    refit_depth_head(again, str(tiny_dataset_master), cfg, overwrite=True)
    model = WorldModel.from_pretrained(run)
    a, b = load_refit_head(run, model).state_dict(), load_refit_head(again, model).state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_second_refit_needs_overwrite_and_too_many_frames_is_one_line(refit_run, tiny_dataset_master):
    run, _ = refit_run
    res = runner.invoke(app, ["depth", str(run), str(tiny_dataset_master), *SMALL])
    assert res.exit_code == 2 and "--overwrite" in res.output and "Traceback" not in res.output
    res = runner.invoke(app, ["depth", str(run), str(tiny_dataset_master), "--frames", "10000000", "--overwrite"])
    assert res.exit_code == 2 and "--frames" in res.output and len(res.output.strip().splitlines()) == 1


def test_the_planner_flies_the_refit_head_when_there_is_one(refit_run, tiny_run):
    run, _ = refit_run
    auto, _ = build_pilot("oracle-true-dyn-depth", run, planner_config())
    stage1, _ = build_pilot("oracle-true-dyn-depth", run, planner_config(depth_head="stage1"))
    plain, _ = build_pilot("oracle-true-dyn-depth", tiny_run, planner_config())  # no RUN/depth: Stage I's
    assert (auto.depth.name, stage1.depth.name, plain.depth.name) == ("refit", "stage1", "stage1")
    assert auto.metadata()["depth_source"] == "refit"
    image = torch.randint(0, 255, (64, 64, 3), dtype=torch.uint8).numpy()
    assert not (auto.depth({"image": image}) == stage1.depth({"image": image})).all()
    with pytest.raises(RunError, match="orbitmodel depth"):
        build_pilot("oracle-true-dyn-depth", tiny_run, planner_config(depth_head="refit"))
    with pytest.raises(ValueError, match="depth_head"):
        planner_config(depth_head="best head")


def test_a_refit_of_other_weights_is_refused(refit_run, tmp_path):
    """A Stage I run trained again after its refit: the planner must not fly the stale head."""
    from safetensors.torch import load_file, save_file

    run = tmp_path / "retrained"
    shutil.copytree(refit_run[0], run)
    weights = load_file(run / "model.safetensors")
    weights["predictor.pos"] = weights["predictor.pos"] + 1.0
    save_file(weights, run / "model.safetensors")
    with pytest.raises(RunError, match="refitted on another world model"):
        load_refit_head(run, WorldModel.from_pretrained(run))


def test_a_named_head_sits_beside_the_runs_own_and_the_planner_flies_it_by_name(refit_run, tiny_dataset_master):
    """A head refitted on another dataset's frames (the dynamic tier's) goes to RUN/depth-NAME; the
    run's own head, its Stage I weights and its other sub-runs stay as they were."""
    from orbitmodel.publish.files import named_heads, run_files

    run, _ = refit_run
    own = (run / "depth" / "model.safetensors").read_bytes()
    res = runner.invoke(app, ["depth", str(run), str(tiny_dataset_master), *SMALL, "--seed", "3", "--name", "tier"])
    assert res.exit_code == 0, res.output
    assert f"wrote {run / 'depth-tier'}" in res.output
    assert (run / "depth" / "model.safetensors").read_bytes() == own
    model = WorldModel.from_pretrained(run)
    named = load_refit_head(run, model, "tier").state_dict()
    assert any(not torch.equal(a, named[k]) for k, a in load_refit_head(run, model).state_dict().items())

    pilot, _ = build_pilot("oracle-true-dyn-depth", run, planner_config(depth_head="tier"))
    auto, _ = build_pilot("oracle-true-dyn-depth", run, planner_config())
    assert (pilot.depth.name, auto.depth.name) == ("refit-tier", "refit")
    assert pilot.metadata()["depth_source"] == "refit-tier"
    image = torch.randint(0, 255, (64, 64, 3), dtype=torch.uint8).numpy()
    assert not (pilot.depth({"image": image}) == auto.depth({"image": image})).all()
    (run / "depth-refit").mkdir()  # a folder no head name can give is no head, and does not go up
    assert named_heads(run) == ("depth-tier",)
    assert {"depth-tier/model.safetensors", "depth-tier/config.json"} <= {f.rel for f in run_files(run)}

    with pytest.raises(RunError, match="--name other"):
        build_pilot("oracle-true-dyn-depth", run, planner_config(depth_head="other"))
    with pytest.raises(ValueError, match="--name NAME"):
        planner_config(depth_head="Tier!")
    for bad in (["--name", "refit"], ["--name", "Tier"], ["--name", "tier", "--imagined"]):
        res = runner.invoke(app, ["depth", str(run), str(tiny_dataset_master), *SMALL, *bad])
        assert res.exit_code == 2 and "--name" in res.output and len(res.output.strip().splitlines()) == 1, bad
    res = runner.invoke(app, ["depth", str(run), str(tiny_dataset_master), *SMALL, "--name", "tier"])
    assert res.exit_code == 2 and "--overwrite" in res.output
