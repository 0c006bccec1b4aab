"""A grid flight cut short (``kill -9``, out of time) continues when the same command runs again:
the chunks it finished are kept beside its table and not flown again, and the table is the one
an uncut flight writes; a changed command flies afresh."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from orbitmodel.cli.app import app
from orbitmodel.evaluate import lockstep
from orbitmodel.evaluate.closed_loop import ClosedLoop
from orbitmodel.evaluate.kept_chunks import ChunkLog, chunk_log_path

runner = CliRunner()
HELPER = Path(__file__).with_name("kill_after_chunks.py")
# 8 episodes, 2 at a time: four chunks of one batch each (the helper's and the fixture's chunk size)
GRID = ["--pilot", "oracle-true", "--obstacles", "1,3", "--speeds", "1,2", "--episodes", "2", "--max-steps", "8"]
FLIGHT = ["eval", "closed-loop", *GRID, "--set", "samples=8", "--set", "horizon=5", "--batch", "2"]
MEASURED = ("latency_ms", "time_share")  # timings: what a flight measures, not what it flew


@pytest.fixture
def flown_chunks(monkeypatch) -> list[range]:
    """Chunks of one batch each in this process, and the chunks it flies, as it flies them."""
    monkeypatch.setattr(lockstep, "ROUNDS_PER_CHUNK", 1)
    flown, fly_chunk = [], ClosedLoop.fly_chunk
    monkeypatch.setattr(ClosedLoop, "fly_chunk", lambda self, part, *a: flown.append(part) or fly_chunk(self, part, *a))
    return flown


def flown(report: dict) -> dict:
    """A table without what its flight measured (latencies, time shares)."""
    episodes = [{k: v for k, v in e.items() if "_ms_" not in k} for e in report["episodes"]]
    return {**{k: v for k, v in report.items() if k not in MEASURED}, "episodes": episodes}


def test_a_killed_flight_continues_from_its_kept_chunks(tmp_path, flown_chunks):
    cut = tmp_path / "grid" / "oracle.json"
    log = chunk_log_path(cut)
    killed = subprocess.run([sys.executable, str(HELPER), "2", *FLIGHT, "--json", str(cut)], capture_output=True)
    assert killed.returncode == -signal.SIGKILL and not cut.exists(), killed.stderr.decode()[-2000:]
    lines = log.read_text().splitlines()
    assert len(lines) == 3  # the flight's key, then its first two chunks
    kept = [json.loads(line) for line in lines[1:]]
    assert [c["chunk"] for c in kept] == [[0, 2], [2, 4]]
    with log.open("a") as f:
        f.write(lines[2][:40])  # and a line cut half-way, as a kill while writing leaves it

    res = runner.invoke(app, [*FLIGHT, "--json", str(cut)])
    assert res.exit_code == 0, res.output
    assert f"resuming: 4 of 8 episodes were flown by a cut flight ({log})" in res.output
    assert flown_chunks == [range(4, 6), range(6, 8)]  # only what the kill left
    assert not log.exists()  # the table is written: nothing left to continue
    report = json.loads(cut.read_text())
    # the kept episodes are the killed flight's, latencies and all
    assert report["episodes"][:4] == [e["record"] for c in kept for e in c["episodes"]]

    straight = tmp_path / "straight.json"
    res = runner.invoke(app, [*FLIGHT, "--json", str(straight)])
    assert res.exit_code == 0 and "resuming" not in res.output, res.output
    assert flown(report) == flown(json.loads(straight.read_text()))  # the uncut flight's table
    assert len(report["episodes"]) == 8 and sum(s["episodes"] for s in report["settings"]) == 8


def test_a_changed_command_flies_afresh(tmp_path, flown_chunks):
    out = tmp_path / "oracle.json"
    log = chunk_log_path(out)
    first = runner.invoke(app, [*FLIGHT, "--json", str(out)])
    assert first.exit_code == 0 and not log.exists(), first.output
    ChunkLog(log, "another flight's key").start({})  # what a cut flight of another command leaves
    flown_chunks.clear()
    res = runner.invoke(app, [*FLIGHT, "--set", "samples=9", "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert f"note: {log} was left by another flight" in res.output and "resuming" not in res.output
    assert flown_chunks == [range(0, 2), range(2, 4), range(4, 6), range(6, 8)] and not log.exists()
    assert json.loads(out.read_text())["planner"]["mppi"]["samples"] == 9


def test_a_cut_flight_of_the_same_request_on_another_run_state_is_another_flight(probed_run, tmp_path):
    """The key holds the weights' state: refitting a part of the run (here its probe's card
    rewritten) makes the chunks a cut flight left another flight's."""
    import dataclasses
    import shutil

    from orbitmodel.evaluate.closed_loop import ClosedLoopRequest
    from orbitmodel.plan.config import planner_config

    run = tmp_path / "run"
    shutil.copytree(probed_run, run)
    req = ClosedLoopRequest(run=run, settings=planner_config("cpu", samples=8, horizon=5), preset="cpu", max_steps=4)
    key = ClosedLoop(req).key()
    assert ClosedLoop(req).key() == key  # the same request on the same run: one flight
    assert ClosedLoop(dataclasses.replace(req, executor="ray")).key() == key  # wherever its chunks fly
    assert ClosedLoop(dataclasses.replace(req, batch=2)).key() != key
    card = run / "probe" / "config.json"
    card.write_text(card.read_text())  # rewritten: a refit
    assert ClosedLoop(req).key() != key
