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


@pytest.mark.parametrize(
    "content, says",
    [(None, "does not exist"), ("[1, 2]", "not a JSON object"), ("{", "is not JSON"), ("7", "not a JSON object")],
)
def test_eval_merge_names_a_part_that_is_not_a_grid_result(tmp_path, content, says):
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"settings": [], "episodes": []}))
    part = tmp_path / "part.json"
    if content is not None:
        part.write_text(content)
    res = runner.invoke(app, ["eval", "merge", str(good), str(part), "--json", str(tmp_path / "merged.json")])
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and "Traceback" not in res.output, res.output
    assert str(part) in lines[0] and says in lines[0], lines[0]
    assert not (tmp_path / "merged.json").exists()
