"""`orbitdata fly`: the grid table, its JSON, and clear errors for bad flags."""

import json

import pytest
from typer.testing import CliRunner

from orbitdata.cli.app import app

runner = CliRunner()


def test_fly_writes_the_json_grid(tmp_path):
    out = tmp_path / "grid.json"
    res = runner.invoke(
        app,
        [
            "fly",
            "--pilot",
            "risky",
            "--obstacles",
            "0,5",
            "--speeds",
            "2",
            "--episodes",
            "2",
            "--seed",
            "0",
            "--json",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    assert report["pilot"] == "risky"
    cells = {(s["obstacles"], s["speed"]): s for s in report["settings"]}
    assert set(cells) == {(0, 2.0), (5, 2.0)}
    for s in report["settings"]:
        assert s["episodes"] == 2
        assert s["success"] + s["collision"] + s["timeout"] + s["out_of_fuel"] == 2
    assert cells[(0, 2.0)]["success"] == 2  # nothing to hit
    assert "success" in res.output


def test_fly_writes_videos(tmp_path):
    res = runner.invoke(
        app,
        [
            "fly",
            "--pilot",
            "risky",
            "--obstacles",
            "5",
            "--speeds",
            "2",
            "--episodes",
            "1",
            "--video",
            str(tmp_path / "v"),
            "--video-format",
            "gif",
            "--image-size",
            "32",
        ],
    )
    assert res.exit_code == 0, res.output
    (video,) = (tmp_path / "v").glob("*.gif")
    from PIL import Image

    with Image.open(video) as im:
        assert im.n_frames > 5 and im.size == (64, 32)  # camera beside the top-down map


@pytest.mark.parametrize(
    "args, message",
    [
        (["--pilot", "reckless"], "--pilot"),
        (["--obstacles", ""], "comma-separated"),
        (["--speeds", ","], "comma-separated"),
        (["--obstacles", "1,x"], "comma-separated"),
        (["--obstacles", "1,,3"], "'1,,3' must be a comma-separated list"),
        (["--episodes", "-3"], "--episodes"),
        (["--obstacles", "-1"], "0 to 1000"),
        (["--obstacles", "99999999999999999999"], "0 to 1000"),
        (["--thrust-noise", "inf"], "finite sigma"),
        (["--speeds", "-2"], ">= 0"),
        (["--video-format", "avi"], "--video-format"),
        (["--pilot", "expert", "--pilot-option", "plan_draw=two"], "plan_draw"),
    ],
)
def test_bad_flags_give_one_line_errors(args, message):
    res = runner.invoke(app, ["fly", *args])
    assert res.exit_code == 2
    assert message in res.output
    assert "Traceback" not in res.output
