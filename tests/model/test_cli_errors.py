"""orbitmodel's one-line errors: an interrupt names the way back only where it exists, and a part
of a grid that is not a grid result is named, never a traceback."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from orbitdata.cli.errors import run_app
from orbitmodel.cli.app import app
from orbitmodel.cli.errors import friendly

runner = CliRunner()


def test_an_interrupt_offers_resume_only_to_a_command_that_takes_it(capsys):
    @friendly
    def train(resume: bool = False) -> None:
        raise KeyboardInterrupt

    @friendly
    def closed_loop(episodes: int = 1) -> None:
        raise KeyboardInterrupt

    for command, says in (
        (train, "run the same command with --resume to continue"),
        (closed_loop, "run the same command again"),
    ):
        with pytest.raises(SystemExit) as exit_:
            command()
        err = capsys.readouterr().err
        assert exit_.value.code == 130 and err == f"interrupted; {says}\n", err


GRID = {
    "pilot": "planner",
    "seed": 3,
    "settings": [{"obstacles": 1, "speed": 1.0, "episodes": 1, "success": 1}],
    "episodes": [{"obstacles": 1, "speed": 1.0, "episode": 0, "seed": 11, "outcome": "success"}],
}


@pytest.mark.parametrize(
    "content, says",
    [
        (None, "does not exist"),
        ("[1, 2]", "not a JSON object"),
        ("{", "is not JSON"),
        ("7", "not a JSON object"),
        ('{"flips": 0, "episodes": 3}', "is not a grid result"),  # eval flips' own --json
    ],
)
def test_eval_merge_names_a_part_that_is_not_a_grid_result(tmp_path, content, says):
    good = tmp_path / "good.json"
    good.write_text(json.dumps(GRID))
    part = tmp_path / "part.json"
    if content is not None:
        part.write_text(content)
    res = runner.invoke(app, ["eval", "merge", str(good), str(part), "--json", str(tmp_path / "merged.json")])
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and "Traceback" not in res.output, res.output
    assert str(part) in lines[0] and says in lines[0], lines[0]
    assert not (tmp_path / "merged.json").exists()


@pytest.mark.parametrize(
    "command",
    [
        ["eval", "factors", "{a}"],
        ["eval", "flips", "{a}", "{b}"],
        ["eval", "pool", "{a}", "{b}"],
        ["eval", "merge", "{a}", "{b}"],
    ],
)
def test_an_eval_json_that_would_overwrite_an_input_is_refused(tmp_path, command):
    a, b = tmp_path / "seed3.json", tmp_path / "seed4.json"
    a.write_text(json.dumps(GRID))
    b.write_text(json.dumps({**GRID, "seed": 4, "settings": [{**GRID["settings"][0], "speed": 2.0}]}))
    before = a.read_text()
    args = [x.format(a=a, b=b) for x in command]
    res = runner.invoke(app, [*args, "--json", str(tmp_path / "." / "seed3.json")])
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1, res.output
    assert "is one of the inputs" in lines[0] and a.read_text() == before
    res = runner.invoke(app, [*args, "--json", str(tmp_path)])
    assert res.exit_code == 2 and "is a folder" in res.output, res.output


def test_eval_flips_names_a_file_that_is_not_a_grid_result(tmp_path):
    grid, comparison = tmp_path / "grid.json", tmp_path / "flips.json"
    grid.write_text(json.dumps(GRID))
    res = runner.invoke(app, ["eval", "flips", str(grid), str(grid), "--json", str(comparison)])
    assert res.exit_code == 0 and "0 of 1 episodes flip" in res.output, res.output
    res = runner.invoke(app, ["eval", "flips", str(comparison), str(grid)])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert f"{comparison} is not a grid result" in res.output


def test_a_dataset_that_is_neither_a_folder_nor_on_the_hub_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")  # nothing reaches the network
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["train", "runs/d20", "--preset", "tiny", "--out", "wm", "--max-steps", "1"])
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 1 and len(lines) == 1 and "Traceback" not in res.output, res.output
    assert lines[0].startswith("error: no local folder runs/d20, and cannot fetch"), lines[0]
    assert not (tmp_path / "wm").exists()


@pytest.mark.parametrize(
    "args",
    [
        ["train", "DATA", "--lr", "0"],
        ["probe", "RUN", "DATA", "--lr", "-0.001"],
        ["train-policy", "DATA", "--lr", "inf"],
        ["depth", "RUN", "DATA", "--lr", "0"],
        ["depth", "RUN", "DATA", "--near-m", "0"],
    ],
)
def test_a_rate_or_range_that_must_be_above_zero_is_refused_as_usage(args, capsys):
    with pytest.raises(SystemExit) as exit_:
        run_app(app, args)
    err = capsys.readouterr().err
    assert exit_.value.code == 2
    assert err.startswith(f"error: {args[-2]}: {args[-1]} must be a finite number above 0 "), err
    assert len(err.splitlines()) == 1
    assert "above 0" in runner.invoke(app, [args[0], "--help"]).output  # not "x>=0.0"


def edited(grid: dict, edit) -> dict:
    grid = json.loads(json.dumps(grid))
    edit(grid)
    return grid


@pytest.mark.parametrize(
    "command",
    [["factors"], ["flips", "GOOD"], ["pool", "GOOD"], ["figure6", "--out", "OUT/f.png"]],
    ids=["factors", "flips", "pool", "figure6"],
)
@pytest.mark.parametrize(
    "edit, says",
    [
        (lambda g: g["episodes"][0].pop("outcome"), "an episode in it has no 'outcome' key"),
        (lambda g: g["settings"][0].update(episodes=0, success=0), "a setting counts 0 successes in 0 episodes"),
        (lambda g: g["settings"][0].update(success=2), "a setting counts 2 successes in 1 episodes"),
        (lambda g: g.update(episodes={"a": 1}), "its settings or episodes are not lists of tables"),
    ],
    ids=["no-outcome", "no-episodes", "more-successes-than-episodes", "episodes-not-a-list"],
)
def test_a_hand_edited_grid_is_named_not_a_traceback(tmp_path, command, edit, says):
    good, bad = tmp_path / "good.json", tmp_path / "bad.json"
    good.write_text(json.dumps(edited(GRID, lambda g: g.update(seed=4))))
    bad.write_text(json.dumps(edited(GRID, edit)))
    args = [str(good) if a == "GOOD" else a.replace("OUT", str(tmp_path)) for a in command]
    res = runner.invoke(app, ["eval", args[0], str(bad), *args[1:]])
    assert res.exit_code == 2, res.output
    assert res.output.startswith(f"error: {bad} is not a grid result ({says})"), res.output
    assert "Traceback" not in res.output and len(res.output.splitlines()) == 1


def test_factors_names_a_record_its_grid_lacks(tmp_path):
    old = tmp_path / "old.json"
    old.write_text(json.dumps(GRID))  # no min_clearance_m: not written by this version's flights
    res = runner.invoke(app, ["eval", "factors", str(old)])
    assert res.exit_code == 2 and res.output.startswith(f"error: {old}: an episode has no 'min_clearance_m' record")
