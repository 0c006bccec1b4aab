"""Without matplotlib (the ``viz`` extra) every command that draws says so in one line, with the
install hint and exit code 1, never a traceback; and what it computed before drawing is kept."""

from __future__ import annotations

import json
import sys

import pytest
from typer.testing import CliRunner

from orbitmodel.cli.app import app

runner = CliRunner()


@pytest.fixture
def no_matplotlib(monkeypatch):
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # `import matplotlib` now raises ImportError


def one_line_hint(res) -> str:
    assert res.exit_code == 1, res.output
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert lines and lines[-1].startswith("error:") and "Traceback" not in res.output, res.output
    assert "pip install 'orbitdata[viz]'" in lines[-1]
    return lines[-1]


def test_figure6_without_matplotlib(no_matplotlib, tmp_path):
    result = {
        "pilot": "expert",
        "seed": 0,
        "settings": [
            {"obstacles": 1, "speed": 1.0, "episodes": 1, "success": 1, "collision": 0, "timeout": 0, "out_of_fuel": 0}
        ],
    }
    (tmp_path / "e.json").write_text(json.dumps(result))
    assert "matplotlib" in one_line_hint(
        runner.invoke(app, ["eval", "figure6", str(tmp_path / "e.json"), "--out", str(tmp_path / "f.png")])
    )
    assert not (tmp_path / "f.png").exists()


def test_eval_rollout_without_matplotlib(no_matplotlib, tiny_run, tiny_dataset_master, tmp_path):
    res = runner.invoke(
        app,
        [
            "eval",
            "rollout",
            str(tiny_run),
            str(tiny_dataset_master),
            "--windows",
            "2",
            "--horizon",
            "2",
            "--out",
            str(tmp_path / "eval"),
        ],
    )
    assert "matplotlib" in one_line_hint(res)
    assert json.loads((tmp_path / "eval" / "rollout.json").read_text())["nmse"]  # the numbers are written
