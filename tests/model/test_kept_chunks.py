"""A grid flight cut short (``kill -9``, out of time) continues when the same command runs again:
the chunks it finished are kept beside its table and not flown again, and the table is the one
an uncut flight writes; a changed command flies afresh."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from orbitmodel.cli.app import app
from orbitmodel.evaluate import lockstep
from orbitmodel.evaluate.closed_loop import ClosedLoop, ClosedLoopRequest
from orbitmodel.evaluate.kept_chunks import ChunkLog, chunk_log_path, flight_lock
from orbitmodel.evaluate.lockstep import ChunkResult, FlownEpisode
from orbitmodel.plan.config import planner_config

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


def cut(flight: list[str], out: Path, after: int) -> list[dict]:
    """Fly ``flight`` into ``out`` in another process, SIGKILLed once ``after`` chunks are kept;
    the chunks it kept."""
    killed = subprocess.run(
        [sys.executable, str(HELPER), str(after), *flight, "--json", str(out)], capture_output=True, timeout=600
    )
    assert killed.returncode == -signal.SIGKILL and not out.exists(), killed.stderr.decode()[-2000:]
    lines = chunk_log_path(out).read_text().splitlines()
    assert len(lines) == after + 1  # the flight's key, then its chunks
    return [json.loads(line) for line in lines[1:]]


def flown(report: dict) -> dict:
    """A table without what its flight measured (latencies, time shares)."""
    episodes = [{k: v for k, v in e.items() if "_ms_" not in k} for e in report["episodes"]]
    return {**{k: v for k, v in report.items() if k not in MEASURED}, "episodes": episodes}


def test_a_killed_flight_continues_from_its_kept_chunks(tmp_path, flown_chunks):
    out = tmp_path / "grid" / "oracle.json"
    log = chunk_log_path(out)
    kept = cut(FLIGHT, out, 2)
    assert [c["chunk"] for c in kept] == [[0, 2], [2, 4]]
    with log.open("a") as f:
        f.write(log.read_text().splitlines()[2][:40])  # and a line cut half-way, as a kill while writing leaves it

    lock = out.with_name("oracle.json.lock")
    assert lock.exists()  # the killed flight's, no longer held: it does not stop the next flight
    res = runner.invoke(app, [*FLIGHT, "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert not lock.exists()
    assert f"resuming: 4 of 8 episodes were flown by a cut flight ({log})" in res.output
    assert flown_chunks == [range(4, 6), range(6, 8)]  # only what the kill left
    assert not log.exists()  # the table is written: nothing left to continue
    report = json.loads(out.read_text())
    # the kept episodes are the killed flight's, latencies and all; the stream holds every episode
    assert report["episodes"][:4] == [e["record"] for c in kept for e in c["episodes"]]
    streamed = [json.loads(line) for line in out.with_suffix(".episodes.jsonl").read_text().splitlines()]
    assert sorted(streamed, key=lambda e: (e["episode"], e["obstacles"], e["speed"])) == report["episodes"]

    straight = tmp_path / "straight.json"
    res = runner.invoke(app, [*FLIGHT, "--json", str(straight)])
    assert res.exit_code == 0 and "resuming" not in res.output, res.output
    assert flown(report) == flown(json.loads(straight.read_text()))  # the uncut flight's table
    assert len(report["episodes"]) == 8 and sum(s["episodes"] for s in report["settings"]) == 8


def test_a_changed_command_flies_afresh(tmp_path, flown_chunks):
    out = tmp_path / "oracle.json"
    log = chunk_log_path(out)
    cut(FLIGHT, out, 1)
    res = runner.invoke(app, [*FLIGHT, "--set", "samples=9", "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert f"note: {log} was left by another flight" in res.output and "resuming" not in res.output
    assert flown_chunks == [range(0, 2), range(2, 4), range(4, 6), range(6, 8)] and not log.exists()
    assert json.loads(out.read_text())["planner"]["mppi"]["samples"] == 9


def test_a_second_flight_to_the_same_table_is_refused(tmp_path, flown_chunks):
    out = tmp_path / "grid" / "oracle.json"
    with flight_lock(out):  # a flight of this table under way (the lock is per open file, so this process counts)
        res = runner.invoke(app, [*FLIGHT, "--json", str(out)])
        assert res.exit_code == 2, res.output
        assert f"{out}: another flight (process {os.getpid()}) is flying this table now" in res.output
        assert "Traceback" not in res.output
        assert flown_chunks == [] and not chunk_log_path(out).exists() and not out.exists()
    assert not out.with_name("oracle.json.lock").exists()  # gone with the flight that held it
    res = runner.invoke(app, [*FLIGHT, "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert len(flown_chunks) == 4 and out.exists()
    table = tmp_path / "grid.lock"  # a table named like a lock is not its own lock
    table.write_text("{}")
    with flight_lock(table):
        pass
    assert table.read_text() == "{}"


def test_another_flights_chunks_stay_until_the_new_flights_first_chunk_lands(tmp_path):
    log = tmp_path / "grid.chunks.jsonl"
    parts = [range(0, 1), range(1, 2)]
    record = {"obstacles": 1, "speed": 1.0, "episode": 0, "outcome": "success"}
    chunk = ChunkResult(range(0, 1), [FlownEpisode(0, record, [1.5], [])], {"rollout": 0.25})
    old = ChunkLog(log, "old")
    old.resume(parts)
    old.add(chunk)
    old.close()
    before = log.read_text()
    new = ChunkLog(log, "new")
    assert new.resume(parts) == {} and new.replaced
    assert log.read_text() == before  # a flight cut before its first chunk has lost nothing of the old one
    new.add(dataclasses.replace(chunk, part=range(1, 2), episodes=[FlownEpisode(1, record, [], [])]))
    new.close()
    assert json.loads(log.read_text().splitlines()[0]) == {"key": "new"}
    again = ChunkLog(log, "new")
    assert list(again.resume(parts)) == [1] and not again.replaced
    assert ChunkLog(log, "old").resume(parts) == {}  # the old flight's chunks are gone now
    log.write_bytes(b"\xff\xfe not text")
    odd = ChunkLog(log, "new")
    assert odd.resume(parts) == {} and odd.replaced  # unreadable: another flight's, replaced in turn


def test_the_key_names_the_request_the_run_and_the_threads(probed_run, tmp_path, monkeypatch):
    """The same request on the same run is one flight wherever its chunks fly; another setting,
    seed, frame limit, batch, thread count or a refitted part of the run is another."""
    run = tmp_path / "run"
    shutil.copytree(probed_run, run)
    req = ClosedLoopRequest(run=run, settings=planner_config("cpu", samples=8, horizon=5), preset="cpu", max_steps=4)
    key = ClosedLoop(req).key()
    assert ClosedLoop(req).key() == key
    assert ClosedLoop(dataclasses.replace(req, executor="ray")).key() == key
    others = [
        dict(settings=planner_config("cpu", samples=9, horizon=5)),
        dict(seed=1),
        dict(max_steps=5),
        dict(batch=2),
    ]
    assert all(ClosedLoop(dataclasses.replace(req, **change)).key() != key for change in others)
    monkeypatch.setattr(torch, "get_num_threads", lambda: 7)
    assert ClosedLoop(req).key() != key
    monkeypatch.undo()
    logs, checkpoints = run / "tensorboard", run / "checkpoints"
    logs.mkdir(exist_ok=True)
    checkpoints.mkdir(exist_ok=True)
    (logs / "config.json").write_text("{}")
    (checkpoints / "step_00000099.safetensors").write_bytes(b"not flown: no pointer names it")
    assert ClosedLoop(req).key() == key  # training logs and unnamed checkpoints are not what a pilot loads
    (checkpoints / "latest").write_text("step_00000099")
    pointed = ClosedLoop(req).key()
    assert pointed != key
    card = run / "probe" / "config.json"
    card.write_text(card.read_text())  # rewritten: a refit
    assert ClosedLoop(req).key() != pointed
