"""scripts/snapshot_checkpoints.sh keeps every EVERY-th checkpoint of a training run as a run folder,
and stops at the run's end, not at the old end of a run trained on with --resume --extend."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

SCRIPT = Path(__file__).parents[2] / "scripts" / "snapshot_checkpoints.sh"


def checkpoint(run: Path, step: int) -> None:
    folder = run / "checkpoints" / f"step-{step:07d}"
    folder.mkdir(parents=True)
    (folder / "model.safetensors").write_text(f"weights at {step}")
    (run / "checkpoints" / "latest").write_text(folder.name + "\n")


def fake_run(path: Path, max_steps: int, steps: list[int], final: bool) -> Path:
    path.mkdir()
    (path / "config.json").write_text(json.dumps({"preset": {"train": {"max_steps": max_steps}}}, indent=2))
    for step in steps:
        checkpoint(path, step)
    if final:
        (path / "model.safetensors").write_text("final")
    return path


def start(run: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        ["bash", str(SCRIPT), str(run), "4", str(out)],
        env={"SNAPSHOT_POLL_S": "0.2", "PATH": "/usr/bin:/bin"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_a_finished_run_is_snapshotted_and_the_script_stops(tmp_path):
    run = fake_run(tmp_path / "run", 8, [4, 8], final=True)
    done = start(run, tmp_path / "snaps")
    assert done.wait(timeout=30) == 0, done.stderr.read()
    assert sorted(p.name for p in (tmp_path / "snaps").iterdir()) == ["step-4", "step-8"]
    assert (tmp_path / "snaps" / "step-8" / "model.safetensors").read_text() == "weights at 8"
    assert json.loads((tmp_path / "snaps" / "step-8" / "config.json").read_text())["preset"]["train"]["max_steps"] == 8


def test_an_extended_run_is_followed_to_its_new_end(tmp_path):
    run = fake_run(tmp_path / "run", 12, [4], final=True)  # the old end's weights are still there
    proc = start(run, tmp_path / "snaps")
    try:
        deadline = time.monotonic() + 30
        while not (tmp_path / "snaps" / "step-4").exists():  # one scan done: it has seen the old end
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.05)
        time.sleep(1.0)  # five more polls
        assert proc.poll() is None, proc.stderr.read()  # did not stop at the old end
        checkpoint(run, 8)
        checkpoint(run, 12)
        assert proc.wait(timeout=30) == 0, proc.stderr.read()
    finally:
        proc.kill()
    assert sorted(p.name for p in (tmp_path / "snaps").iterdir()) == ["step-12", "step-4", "step-8"]
