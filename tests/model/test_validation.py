"""The validation split: a seeded fraction of the train split's episodes, held out of every
training stage of a run and recorded in it; choices are made on it (``--split val``), the test
split only reports."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitdata.load import load_windows
from orbitdata.load.tables import load_episode_table
from orbitmodel.cli.app import app
from orbitmodel.data import ValidationSplit, split_selection, training_episodes, validation_split

runner = CliRunner()


def test_the_split_is_a_seeded_fraction_of_every_level(tiny_dataset_master):
    table = load_episode_table(tiny_dataset_master, "train", {}).to_pylist()
    levels = {e[S.EPISODE_INDEX]: e[S.LEVEL] for e in table}
    split = validation_split(tiny_dataset_master, 0.5, seed=3)
    assert split == validation_split(tiny_dataset_master, 0.5, seed=3)  # same seed, same episodes
    assert split.episodes and set(split.episodes) < set(levels)
    for level in set(levels.values()):  # never a whole level, so every level still trains
        assert any(levels[e] == level for e in levels if e not in split.episodes)
    assert validation_split(tiny_dataset_master, 0.0, seed=3).episodes == ()
    assert ValidationSplit.from_dict(json.loads(json.dumps(split.to_dict()))) == split
    kept = training_episodes(tiny_dataset_master, (), (), split)
    assert sorted(set(kept) | set(split.episodes)) == sorted(levels) and not set(kept) & set(split.episodes)
    with pytest.raises(ValueError, match="holds out no validation episodes; train it with --val-fraction"):
        split_selection("val", validation_split(tiny_dataset_master, 0.0, 0))
    with pytest.raises(ValueError, match=r"\[0, 1\)"):
        validation_split(tiny_dataset_master, 1.0, 0)


def test_a_run_holds_its_validation_episodes_out_and_is_evaluated_on_them(tiny_dataset_master, tmp_path, monkeypatch):
    import orbitmodel.plan.depth_refit
    import orbitmodel.probe.train
    import orbitmodel.train.stage1

    trained_on: dict[str, list] = {}  # the episodes= each training stage asked the loader for

    def spy(stage, load):
        def wrapped(*args, **kwargs):
            if kwargs.get("split") == "train":
                trained_on.setdefault(stage, []).append(kwargs.get("episodes"))
            return load(*args, **kwargs)

        return wrapped

    for module, stage in ((orbitmodel.train.stage1, "stage1"), (orbitmodel.probe.train, "probe")):
        monkeypatch.setattr(module, "load_model_windows", spy(stage, module.load_model_windows))
    patches = orbitmodel.plan.depth_refit._patches

    def fitted_frames(model, dataset, split, n, seed, where, episodes=None):  # the refit's training frames
        if where == "--frames":
            trained_on.setdefault("refit", []).append(episodes)
        return patches(model, dataset, split, n, seed, where, episodes)

    monkeypatch.setattr(orbitmodel.plan.depth_refit, "_patches", fitted_frames)
    run, data = tmp_path / "wm", str(tiny_dataset_master)
    res = runner.invoke(
        app,
        [
            "train",
            data,
            "--preset",
            "tiny",
            "--max-steps",
            "2",
            "--val-fraction",
            "0.5",
            "--device",
            "cpu",
            "--out",
            str(run),
        ],
    )
    assert res.exit_code == 0, res.output
    held_out = ValidationSplit.from_dict(json.loads((run / "config.json").read_text())["validation"])
    assert held_out.fraction == 0.5 and held_out.episodes
    assert held_out == validation_split(tiny_dataset_master, 0.5, 0)
    res = runner.invoke(app, ["probe", str(run), data, "--device", "cpu", "--epochs", "1"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["depth", str(run), data, "--frames", "32", "--test-frames", "16", "--epochs", "1", "--eval-split", "val"]
    )
    assert res.exit_code == 0, res.output
    assert set(trained_on) == {"stage1", "probe", "refit"}
    for stage, calls in trained_on.items():  # every training stage left the validation episodes out
        assert all(isinstance(e, list) and e and not set(e) & set(held_out.episodes) for e in calls), (stage, calls)
    res = runner.invoke(
        app, ["eval", "probe", str(run), data, "--split", "val", "--windows", "1", "--horizon", "2", "--no-figures"]
    )
    assert res.exit_code == 0, res.output
    table = json.loads((run / "eval" / "probe_table.json").read_text())
    assert table["split"] == "val" and set(table["episodes"]) <= set(held_out.episodes)
    res = runner.invoke(
        app,
        [
            "eval",
            "rollout",
            str(run),
            data,
            "--split",
            "val",
            "--windows",
            "2",
            "--horizon",
            "2",
            "--out",
            str(tmp_path / "val"),
        ],
    )
    assert res.exit_code == 0, res.output
    rollout = json.loads((tmp_path / "val" / "rollout.json").read_text())
    assert set(rollout["episodes"]) <= set(held_out.episodes) and rollout["config"]["split"] == "val"
    # the training windows of every stage leave them out
    kept = load_windows(
        data, split="train", context=1, horizon=0, columns=[S.STATE], episodes=training_episodes(data, (), (), held_out)
    )
    assert not set(kept.episodes.tolist()) & set(held_out.episodes)


def test_a_run_without_a_validation_split_refuses_split_val_in_one_line(tiny_run, tiny_dataset_master, tmp_path):
    res = runner.invoke(
        app,
        [
            "eval",
            "rollout",
            str(tiny_run),
            str(tiny_dataset_master),
            "--split",
            "val",
            "--windows",
            "2",
            "--horizon",
            "2",
            "--out",
            str(tmp_path / "x"),
        ],
    )
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and "--val-fraction" in lines[0], res.output


def test_a_policy_run_holds_out_and_is_evaluated_on_its_validation_episodes(tiny_dataset_master, tmp_path, monkeypatch):
    import orbitmodel.baselines.diffusion.evaluate as policy_eval
    import orbitmodel.baselines.diffusion.train as policy_train

    asked: dict[str, list] = {}  # the (split, episodes=) training and evaluation asked the loader for

    def spy(stage, load):
        def wrapped(*args, **kwargs):
            asked.setdefault(stage, []).append((kwargs.get("split"), kwargs.get("episodes")))
            return load(*args, **kwargs)

        return wrapped

    monkeypatch.setattr(policy_train, "load_windows", spy("train", policy_train.load_windows))
    monkeypatch.setattr(policy_eval, "load_windows", spy("eval", policy_eval.load_windows))
    run, data = tmp_path / "dp", str(tiny_dataset_master)
    res = runner.invoke(
        app,
        [
            "train-policy",
            data,
            "--preset",
            "tiny",
            "--max-steps",
            "2",
            "--val-fraction",
            "0.5",
            "--device",
            "cpu",
            "--out",
            str(run),
        ],
    )
    assert res.exit_code == 0, res.output
    held_out = ValidationSplit.from_dict(json.loads((run / "config.json").read_text())["validation"])
    assert held_out == validation_split(tiny_dataset_master, 0.5, 0)
    res = runner.invoke(
        app,
        [
            "eval",
            "policy",
            str(run),
            data,
            "--split",
            "val",
            "--level",
            "expert",
            "--level",
            "exploratory",
            "--level",
            "risky",
            "--stride",
            "8",
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    result = json.loads(res.output)
    assert result["split"] == "val" and result["frames"] > 0
    # Training read the train split without the held-out episodes; the evaluation read those alone.
    ((split, trained),) = asked["train"]
    assert split == "train" and len(trained) > 0 and set(trained).isdisjoint(held_out.episodes)
    ((split, scored),) = asked["eval"]
    assert split == "train" and sorted(scored) == sorted(held_out.episodes)
