"""`orbitdata info`: the summary agrees with the data; table and --json; clear errors, offline."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import orbitdata
from orbitdata import schema as S
from orbitdata.cli.app import app
from orbitdata.load.episodes import read_episodes
from orbitdata.load.source import is_repo_id
from orbitdata.load.summary import summarize

runner = CliRunner()


def test_the_summary_agrees_with_the_episodes_table(tiny_dataset_master):
    s = summarize(tiny_dataset_master)
    rows = read_episodes(tiny_dataset_master).to_pylist()
    lengths = np.array([r[S.LENGTH] for r in rows])
    assert s["episodes"] == len(rows) == 6
    assert s["steps"] == lengths.sum()
    assert s["schema_version"] == S.SCHEMA_VERSION and s["image_size"] == 64 and s["fps"] == S.FPS
    for split, sc in s["counts"]["splits"].items():
        for level, lc in sc["levels"].items():
            mine = [r for r in rows if r[S.SPLIT] == split and r[S.LEVEL] == level]
            assert lc["episodes"] == len(mine)
            assert lc["outcomes"] == {o: sum(r[S.OUTCOME] == o for r in mine) for o in S.OUTCOMES}
    for level, rates in s["outcome_rates"].items():
        assert sum(rates.values()) == pytest.approx(1.0, abs=1e-3)
    all_len = s["lengths"]["all"]
    assert (all_len["min"], all_len["max"], all_len["episodes"]) == (lengths.min(), lengths.max(), len(rows))
    assert all_len["median"] == pytest.approx(np.median(lengths))
    hist = s["lengths"]["histogram"]
    assert sum(sum(h) for h in hist["by_level"].values()) == len(rows)
    assert hist["edges"][0] == 0 and hist["edges"][-1] >= lengths.max()
    info = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())
    assert s["sizes"]["total"] == sum(f["bytes"] for f in info["files"].values())
    assert s["sizes"]["data"].keys() == {r[S.SPLIT] for r in rows}
    assert s["parameters"]["sim"]["camera.image_size"] == 64
    assert "expert.planner.iterations" in s["parameters"]["pilots"]


def test_info_prints_tables(tiny_dataset_master):
    res = runner.invoke(app, ["info", str(tiny_dataset_master)])  # into a pipe: its tables are not cut at 80
    assert res.exit_code == 0, res.output
    for text in (
        "static tier · schema",
        "Episodes per split, level and outcome",
        "Episode length",
        "Sizes",
        "How it was made",
        "expert",
        "success %",
        f"schema {S.SCHEMA_VERSION}",
        "shapes=[sphere",
    ):
        assert text in res.output, text


def test_info_json_is_the_same_summary(tiny_dataset_master):
    res = runner.invoke(app, ["info", str(tiny_dataset_master), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output) == json.loads(json.dumps(summarize(tiny_dataset_master)))


def test_a_repo_id_offline_is_one_clear_line(tmp_path, monkeypatch):
    from huggingface_hub import constants

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", True)
    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)  # so 'nobody/orbit' is no local folder
    res = runner.invoke(app, ["info", "nobody/orbit"])
    assert res.exit_code == 1
    line = res.output.strip()
    assert len(line.splitlines()) == 1 and "Traceback" not in line
    assert "'nobody/orbit'" in line and "HF_HUB_OFFLINE" in line and "local dataset folder" in line


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p / "missing", "no dataset folder at"),
        (lambda p: p, "meta/info.json is missing"),
    ],
)
def test_info_on_something_that_is_not_a_dataset(tmp_path, make, message):
    res = runner.invoke(app, ["info", str(make(tmp_path))])
    assert res.exit_code == 2 and message in res.output  # a usage error
    assert len(res.output.strip().splitlines()) == 1


def test_an_unreachable_hub_is_said_to_be_unreachable_without_retrying(tmp_path):
    """It used to retry for half a minute, then say that the repo had no such file."""
    with socket.socket() as sock:  # a port nothing listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    paths = [str(Path(orbitdata.__file__).parents[1]), os.environ.get("PYTHONPATH", "")]
    env = {k: v for k, v in os.environ.items() if not k.startswith("HF_")}
    env.update(
        PYTHONPATH=os.pathsep.join(p for p in paths if p),
        HF_ENDPOINT=f"http://127.0.0.1:{port}",
        HF_HOME=str(tmp_path / "hf"),
    )
    res = subprocess.run(
        [sys.executable, "-m", "orbitdata", "info", "owner/name"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )  # a guard: a second normally
    assert res.returncode == 1 and res.stdout == ""
    assert res.stderr.strip().splitlines() == [res.stderr.strip()]  # one line: no retry warnings, no traceback
    assert f"the Hugging Face Hub at http://127.0.0.1:{port} could not be reached" in res.stderr
    assert "no such file" not in res.stderr and "'owner/name'" in res.stderr


def test_repo_ids_are_told_from_paths(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert is_repo_id("user/orbit_planner")
    assert not is_repo_id("./user/orbit_planner") and not is_repo_id("/abs/path") and not is_repo_id("name")
    (tmp_path / "user" / "orbit_planner").mkdir(parents=True)
    assert not is_repo_id("user/orbit_planner")  # an existing folder wins


def test_read_meta_gives_the_typed_info_and_the_stats(tiny_dataset_master, tmp_path, monkeypatch):
    from orbitdata import read_meta
    from orbitdata.info import Info
    from orbitdata.load import HubUnavailable

    info, stats = read_meta(tiny_dataset_master)
    raw = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())
    assert isinstance(info, Info) and info.to_dict() == raw
    assert (
        info.image_size == 64 and info.counts["episodes"] == 6 and info.generation_config().sim.camera.image_size == 64
    )
    assert stats == json.loads((tiny_dataset_master / S.STATS_PATH).read_text())
    assert len(stats[S.STATE]["mean"]) == S.STATE_DIM and len(stats[S.IMAGE]["std"]) == 3
    from huggingface_hub import constants

    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", True)
    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(HubUnavailable, match="HF_HUB_OFFLINE"):
        read_meta("nobody/orbit")
