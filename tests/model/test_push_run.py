"""``orbitmodel push``: a run on the (local test) Hub, loaded back by its repo id, flown from it,
and its card's figures read from its own evaluation files."""

from __future__ import annotations

import json
import re
import shutil

import pytest
import torch
from huggingface_hub import ModelCard
from publish.hub_server import TOKEN
from safetensors.torch import load_file, save_file
from typer.testing import CliRunner

from orbitmodel.cli.app import app

runner = CliRunner()
REPO = "tester/tiny-wm"
GRID = [
    "--obstacles",
    "1",
    "--speeds",
    "1",
    "--episodes",
    "1",
    "--max-steps",
    "4",
    "--set",
    "samples=8",
    "--set",
    "horizon=5",
]


@pytest.fixture(scope="module")
def evaluated_run(tiny_run, tiny_dataset_master, tmp_path_factory):
    """The tiny run with its probe, Table I, the rollout evaluation and one flown grid (eval/grid)."""
    from orbitmodel.config import get_preset
    from orbitmodel.probe.train import ProbeRequest, train_probe

    run = tmp_path_factory.mktemp("pushable") / "tiny"
    shutil.copytree(tiny_run, run)
    train_probe(ProbeRequest(run=run, dataset=str(tiny_dataset_master), recipe=get_preset("tiny").probe, device="cpu"))
    data = str(tiny_dataset_master)
    for args in (
        ["eval", "rollout", str(run), data, "--windows", "2", "--horizon", "3"],
        ["eval", "probe", str(run), data, "--windows", "2", "--horizon", "2", "--horizon", "4", "--no-figures"],
        ["eval", "closed-loop", str(run), *GRID, "--json", str(run / "eval" / "grid" / "planner.json")],
    ):
        res = runner.invoke(app, args)
        assert res.exit_code == 0, res.output
    return run


def state_dicts_equal(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_a_pushed_run_loads_by_repo_id_flies_and_works_offline(
    evaluated_run, hub_client, monkeypatch, tiny_dataset_master, tmp_path
):
    from huggingface_hub import constants

    from orbitmodel import PhysicsProbe, WorldModel
    from orbitmodel.plan.factory import make_planner
    from orbitmodel.runs import RunError

    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["push", str(evaluated_run), REPO])
    assert res.exit_code == 0, res.output
    assert TOKEN not in res.output and "pushed" in res.output
    assert not any(TOKEN.encode() in body for body in hub_client.state.bodies)  # the token only in a header
    files = hub_client.files(REPO, kind="models")
    leaks = [
        p for p, data in files.items() if p.endswith((".json", ".md")) and str(evaluated_run.parent).encode() in data
    ]
    assert not leaks, leaks  # no local absolute path is published
    assert {
        "config.json",
        "model.safetensors",
        "probe/config.json",
        "probe/model.safetensors",
        "training.json",
        "eval/probe_table.json",
        "eval/rollout.json",
        "eval/grid/planner.json",
        "README.md",
    } <= set(files)
    assert not [p for p in files if p.startswith("checkpoints/") or "latents" in p]  # nothing only resuming needs
    assert files["model.safetensors"] == (evaluated_run / "model.safetensors").read_bytes()

    local = WorldModel.from_pretrained(evaluated_run)
    hubbed = WorldModel.from_pretrained(REPO)
    assert state_dicts_equal(local, hubbed) and hubbed.fingerprint == local.fingerprint
    assert state_dicts_equal(
        PhysicsProbe.from_pretrained(evaluated_run),
        PhysicsProbe.from_pretrained(f"{REPO}@main", world_model=hubbed.fingerprint),
    )
    pilot = make_planner(_config(), run=REPO, preset="cpu", samples="8", horizon="5")
    assert pilot.name == "planner" and pilot.config.history == 2

    res = runner.invoke(app, ["eval", "closed-loop", REPO, *GRID])  # flown from the repo id
    assert res.exit_code == 0, res.output
    assert "planner pilot, 1 episodes per setting" in res.output
    evals = ["eval", "rollout", REPO, str(tiny_dataset_master), "--windows", "2", "--horizon", "2"]
    res = runner.invoke(app, evals)  # it would write into the repo's cached copy
    assert res.exit_code == 2 and "--local-dir" in res.output and not (tmp_path / "tester").exists()
    assert runner.invoke(app, [*evals, "--out", str(tmp_path / "eval")]).exit_code == 0

    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", True)  # from the cache alone
    assert state_dicts_equal(WorldModel.from_pretrained(REPO), local)
    with pytest.raises(RunError, match="not in the local Hugging Face cache"):
        WorldModel.from_pretrained("tester/never-pushed")


def _config():
    from orbitdata.config import GenerationConfig
    from orbitdata.sim.config import CameraConfig

    config = GenerationConfig()
    return config.__class__(
        **{
            **config.__dict__,
            "sim": config.sim.__class__(**{**config.sim.__dict__, "camera": CameraConfig(image_size=64)}),
        }
    )


def test_the_cards_figures_are_the_eval_files(evaluated_run, hub_client):
    res = runner.invoke(app, ["push", str(evaluated_run), REPO])
    assert res.exit_code == 0, res.output
    card = ModelCard(hub_client.files(REPO, kind="models")["README.md"].decode())
    assert card.data.license == "apache-2.0" and card.data.library_name == "orbitmodel"
    table = json.loads((evaluated_run / "eval" / "probe_table.json").read_text())
    for q, unit in (("position", "m"), ("velocity", "m/s"), ("rotation", "rad"), ("fuel", "ratio")):
        for h in (2, 4):
            e = table["table"]["probe"][q][f"h{h}"]
            assert f"| {q} ({unit}) | {h} | {e['mean']:.4f} ± {e['std']:.4f} |" in card.text, (q, h)
    rollout = json.loads((evaluated_run / "eval" / "rollout.json").read_text())
    assert f"effective rank {rollout['effective_rank']:.1f} of {rollout['latent_dim']}" in card.text
    grid = json.loads((evaluated_run / "eval" / "grid" / "planner.json").read_text())
    k, n = grid["settings"][0]["success"], grid["settings"][0]["episodes"]
    assert re.search(rf"\| planner \| {k}/{n} \| [0-9.]+ % \[[0-9.]+, [0-9.]+\] \({k}/{n}\) \|", card.text)
    assert "within 0.16 s (4 frames)" in card.text  # the episode length the grid was flown with
    assert str(evaluated_run) not in card.text
    segment = json.loads((evaluated_run / "training.json").read_text())["segments"][0]
    assert segment["hardware"] in card.text and "tiny" in card.text and f"--seed {0}" in card.text


def test_an_incomplete_run_is_refused_in_one_line(tiny_run, evaluated_run, hub_client, tmp_path):
    no_probe = tmp_path / "no-probe"
    shutil.copytree(tiny_run, no_probe)
    unfinished = tmp_path / "unfinished"
    shutil.copytree(evaluated_run, unfinished)
    (unfinished / "model.safetensors").unlink()
    retrained = tmp_path / "retrained"  # the world model changed after its probe was trained
    shutil.copytree(evaluated_run, retrained)
    weights = load_file(retrained / "model.safetensors")
    weights["predictor.pos"] = weights["predictor.pos"] + 1.0
    save_file(weights, retrained / "model.safetensors")
    for run, reason in (
        (no_probe, "no physics probe"),
        (unfinished, "training has not finished"),
        (retrained, "another world model"),
        (tmp_path / "nothing", "not an orbitmodel run"),
    ):
        res = runner.invoke(app, ["push", str(run), REPO])
        lines = [line for line in res.output.splitlines() if line.strip()]
        assert res.exit_code == 2 and len(lines) == 1 and reason in lines[0], res.output
    assert not hub_client.state.repos  # nothing was created


def test_dry_run_needs_no_token_and_a_missing_token_is_one_line(evaluated_run, hub_client, monkeypatch):
    monkeypatch.delenv("HF_TOKEN")
    res = runner.invoke(app, ["push", str(evaluated_run), REPO, "--dry-run"])
    assert res.exit_code == 0, res.output
    assert "probe/model.safetensors" in res.output and "Table I" in res.output and "apache-2.0" in res.output
    assert not hub_client.state.requests  # no network
    res = runner.invoke(app, ["push", str(evaluated_run), REPO])
    assert res.exit_code == 1 and "no Hugging Face token found" in res.output and "Traceback" not in res.output


def test_what_is_a_hub_repo_id_and_what_a_local_path(tmp_path, monkeypatch):
    from orbitmodel.runs import RunError, is_hub_run, resolve_run

    monkeypatch.chdir(tmp_path)
    (tmp_path / "runs").mkdir()
    assert is_hub_run("owner/name") and is_hub_run("owner/name@v1")
    assert not is_hub_run("runs/missing")  # its first folder is here: a local path not made yet
    assert not is_hub_run("./owner/name") and not is_hub_run(str(tmp_path / "x")) and not is_hub_run("a")
    with pytest.raises(RunError, match="local path"):
        resolve_run("runs/missing", revision="main")


def test_a_policy_run_round_trips(hub_client, tmp_path):
    from test_diffusion_pilot import PRESET, save_policy_run

    from orbitmodel.baselines.diffusion import DiffusionPolicy

    torch.manual_seed(0)
    policy = DiffusionPolicy(PRESET.model).eval()
    run = save_policy_run(policy, tmp_path / "dp").path
    res = runner.invoke(app, ["push", str(run), "tester/tiny-dp"])
    assert res.exit_code == 0, res.output
    assert state_dicts_equal(DiffusionPolicy.from_pretrained("tester/tiny-dp"), policy)
    card = hub_client.files("tester/tiny-dp", kind="models")["README.md"].decode()
    assert "Diffusion Policy" in card and "No closed-loop results" in card


@pytest.mark.parametrize("repo", ["not a repo id!", "a/b/c", "name-only", "tester/tiny@v1"])
@pytest.mark.parametrize("dry_run", [True, False], ids=["dry-run", "push"])
def test_a_repo_id_that_cannot_exist_is_refused_at_once(evaluated_run, hub_client, repo, dry_run):
    res = runner.invoke(app, ["push", str(evaluated_run), repo, *(["--dry-run"] if dry_run else [])])
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1, res.output
    assert lines[0].startswith(f"error: REPO_ID {repo!r}") and "owner/name" in lines[0]
    assert ("--branch" in lines[0]) == ("@" in repo)
    assert not hub_client.state.requests  # refused before any token or network


def test_a_dataset_id_that_cannot_exist_names_its_flag(evaluated_run, hub_client):
    res = runner.invoke(app, ["push", str(evaluated_run), REPO, "--dry-run", "--dataset", "a/b/c"])
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: --dataset: 'a/b/c'"), res.output


def reproduce_lines(card: str) -> list[str]:
    """The commands of the card's "Reproduce" block."""
    block = card.split("## Reproduce", 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
    return block.strip().splitlines()


def test_the_cards_reproduce_commands_give_the_runs_config(evaluated_run, hub_client, tiny_dataset_master, tmp_path):
    """The tiny run trained with --max-steps 2, which its preset does not: the card's train command
    says so, and running it writes the run's config.json again."""
    res = runner.invoke(app, ["push", str(evaluated_run), REPO, "--dry-run"])
    assert res.exit_code == 0, res.output
    lines = reproduce_lines(res.output)
    train = next(line for line in lines if line.startswith("orbitmodel train "))
    assert "--max-steps 2" in train and "#" not in train, train
    assert "orbitmodel probe RUN DATA" in lines  # the probe trained with its run's recipe: no flags
    out = tmp_path / "again"
    args = train.replace("DATA", str(tiny_dataset_master)).replace("RUN", str(out)).split()[1:]
    res = runner.invoke(app, [*args, "--device", "cpu"])
    assert res.exit_code == 0, res.output
    assert json.loads((out / "config.json").read_text()) == json.loads((evaluated_run / "config.json").read_text())


def test_the_reproduce_commands_flag_each_changed_setting_and_name_the_rest(evaluated_run):
    """A probe trained with other settings than its run's recipe, and a depth refit with others
    than the defaults: each becomes its flag; one that no flag sets is named after the command."""
    from dataclasses import asdict

    from orbitmodel.plan.depth_refit import DepthRefitConfig
    from orbitmodel.publish.reproduce import depth_command, probe_command

    raw = json.loads((evaluated_run / "config.json").read_text())
    probe = json.loads((evaluated_run / "probe" / "config.json").read_text())
    probe["probe"]["integrator"] = "upstream"
    probe["train"].update(cache_windows=16, weights=[1, 1, 1, 1, 0.5])
    probe["train"]["loop"].update(epochs=5, lr=0.0025, warmup=0.3)
    assert probe_command(raw, probe, "latent") == (
        "orbitmodel probe RUN DATA --integrator upstream --epochs 5 --lr 0.0025 --loss-weights 1,1,1,1,0.5 "
        "--cache-windows 16   # no flag sets train.loop.warmup=0.3 (config.json records every setting)"
    )
    refit = {**asdict(DepthRefitConfig()), "frames": 64, "near_weight": 10.0, "eval_split": "val", "batch_size": 32}
    assert depth_command({"refit": refit}) == (
        "orbitmodel depth RUN DATA --frames 64 --near-weight 10 --eval-split val   # no flag sets batch_size=32 "
        "(config.json records every setting)"
    )


def test_a_policy_cards_reproduce_command_gives_the_runs_preset(hub_client, tiny_dataset_master, tmp_path):
    from test_diffusion_pilot import PRESET, save_policy_run

    from orbitmodel.baselines.diffusion import DiffusionPolicy

    preset = PRESET.with_train(max_steps=3, lr=0.002, mask_padding=False, num_workers=0)
    torch.manual_seed(0)
    run = save_policy_run(DiffusionPolicy(preset.model).eval(), tmp_path / "dp", preset).path
    res = runner.invoke(app, ["push", str(run), "tester/tiny-dp", "--dry-run"])
    assert res.exit_code == 0, res.output
    [command] = reproduce_lines(res.output)
    assert command == "orbitmodel train-policy DATA --preset tiny --out RUN --max-steps 3 --lr 0.002 --no-mask-padding"
    out = tmp_path / "again"
    res = runner.invoke(
        app,
        [*command.replace("DATA", str(tiny_dataset_master)).replace("RUN", str(out)).split()[1:], "--device", "cpu"],
    )
    assert res.exit_code == 0, res.output
    again, pushed = (json.loads((folder / "config.json").read_text())["preset"] for folder in (out, run))
    assert again == pushed
