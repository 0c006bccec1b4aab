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
