"""The README's quick start runs as written: its bash block, line for line, in a fresh folder.

The block is read from README.md itself, so the README cannot drift from what works. It runs at
the README's toy sizes (a 40-episode dataset, a few training steps, a few short flights).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def quickstart_block(readme: str) -> str:
    """The first ```bash block under the README's "## Quick start" heading."""
    section = readme.split("\n## Quick start\n", 1)[1].split("\n## ", 1)[0]
    match = re.search(r"```bash\n(.*?)```", section, re.S)
    assert match, "README.md's Quick start has no ```bash block"
    return match.group(1)


def test_the_readme_names_the_six_steps():
    commands = [line.split("#")[0].split() for line in quickstart_block((ROOT / "README.md").read_text()).splitlines()]
    steps = [c[:3] if c[:2] == ["orbitmodel", "eval"] else c[:2] for c in commands if c]
    assert steps == [
        ["source", ".venv/bin/activate"],
        ["orbitdata", "generate"],
        ["orbitmodel", "train"],
        ["orbitmodel", "probe"],
        ["orbitmodel", "depth"],
        ["orbitmodel", "eval", "closed-loop"],
        ["orbitmodel", "eval", "table"],
    ]


def test_the_quick_start_runs_as_written(tmp_path):
    block = quickstart_block((ROOT / "README.md").read_text())
    (tmp_path / ".venv").symlink_to(Path(sys.prefix))  # the README activates ./.venv: this one
    env = {k: v for k, v in os.environ.items() if not k.startswith("HF_")} | {"HF_HUB_OFFLINE": "1"}
    res = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", block], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900
    )
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert (tmp_path / "toy" / "meta" / "info.json").is_file()
    for part in ("model.safetensors", "probe/model.safetensors", "depth/model.safetensors"):
        assert (tmp_path / "toy-wm" / part).is_file(), part
    report = json.loads((tmp_path / "toy-grid" / "planner.json").read_text())
    assert report["pilot"] == "planner" and report["preset"] == "cpu" and len(report["episodes"]) == 12
    assert "| planner |" in res.stdout and "95 % CI" in res.stdout
