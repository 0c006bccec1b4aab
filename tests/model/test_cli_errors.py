"""orbitmodel's one-line errors: an interrupt names the way back only where it exists, and a part
of a grid that is not a grid result is named, never a traceback."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

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
