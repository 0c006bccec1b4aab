"""`orbitmodel --help` and each command's --help load neither torch nor the simulator: the CLI
imports what a command needs when the command runs."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

SCRIPT = """
import json, sys
from orbitmodel.cli.app import app
try:
    app(sys.argv[1:], prog_name="orbitmodel")
except SystemExit as exc:
    code = exc.code or 0
print(json.dumps({"code": code, "heavy": sorted(m for m in ("torch", "mujoco", "ompl", "diffusers")
                                                  if m in sys.modules)}))
"""


@pytest.mark.parametrize(
    "args",
    [
        ["--help"],
        ["eval", "closed-loop", "--help"],
        ["depth", "--help"],
        ["train-policy", "--help"],
        ["eval", "policy", "--help"],
        ["probe", "--help"],
    ],
)
def test_help_loads_no_heavy_module(args):
    res = subprocess.run([sys.executable, "-c", SCRIPT, *args], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    result = json.loads(res.stdout.strip().splitlines()[-1])
    assert result == {"code": 0, "heavy": []}


@pytest.mark.parametrize(
    "args, flag",
    [
        (["eval", "closed-loop", "--episodes", "0"], "--episodes"),
        (["eval", "closed-loop", "--pilot", "autopilot"], "--pilot"),
        (["train", "DATA", "--preset", "huge", "--out", "RUN"], "--preset"),
        (["eval", "closed-loop", "--sample", "8"], "--sample"),
    ],
)
def test_a_range_or_choice_error_is_one_line_naming_the_flag(args, flag):
    """The installed `orbitmodel` program (its main()) turns click's usage errors into one line
    that names the flag, and exits 2: no box, no pydantic wording."""
    code = "import sys; from orbitmodel.cli.app import main; sys.argv[0] = 'orbitmodel'; main()"
    res = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300)
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert lines[0].startswith("error:") and flag in lines[0] and "│" not in lines[0], lines[0]
