"""The light paths load neither MuJoCo nor OMPL: --help, info, validate, push and the read-side API.

Checked in a fresh interpreter each, by looking at ``sys.modules`` after the work is done.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import orbitdata

HEAVY = ("mujoco", "ompl")
SCRIPT = """
import json, sys
kind, args = sys.argv[1], json.loads(sys.argv[2])
code = 0
if kind == "import":
    import importlib
    for name in args:
        module, _, attr = name.partition(":")
        value = importlib.import_module(module)
        if attr:
            getattr(value, attr)
else:
    from orbitdata.cli.app import app
    try:
        app(args, prog_name="orbitdata")
    except SystemExit as exc:
        code = exc.code or 0
print(json.dumps({"code": code, "heavy": sorted(m for m in %r if m in sys.modules)}))
""" % (HEAVY,)


def run(kind: str, args: list[str]) -> dict:
    paths = [str(Path(orbitdata.__file__).parents[1]), os.environ.get("PYTHONPATH", "")]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in paths if p))
    res = subprocess.run(
        [sys.executable, "-c", SCRIPT, kind, json.dumps(args)], env=env, capture_output=True, text=True, timeout=900
    )  # a guard: seconds normally
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize(
    "modules",
    [
        ["orbitdata.load", "orbitdata.load:read_meta", "orbitdata.load.summary", "orbitdata.load.episodes"],
        ["orbitdata.validate", "orbitdata.validate:validate"],
        ["orbitdata.publish", "orbitdata.publish:push"],
        ["orbitdata.state", "orbitdata.codecs", "orbitdata.info", "orbitdata.schema", "orbitdata.config"],
        ["orbitdata.fly", "orbitdata.fly:Pilot", "orbitdata.fly:register_pilot", "orbitdata.fly:list_pilots"],
        ["orbitdata.sim", "orbitdata.sim:SimConfig"],
    ],
)
def test_the_read_side_and_the_contract_import_light(modules):
    assert run("import", modules)["heavy"] == []


def test_importing_the_simulator_does_load_mujoco():  # the check above can see a heavy import
    assert run("import", ["orbitdata.sim:CubeSatEnv"])["heavy"] == ["mujoco"]


def test_light_commands_load_neither_mujoco_nor_ompl(tiny_dataset_master, tmp_path):
    root = str(tiny_dataset_master)
    for args in (
        ["--help"],
        ["info", root],
        ["validate", root, "--workers", "1"],
        ["push", root, "user/orbit", "--dry-run"],
        ["fly", "--help"],
    ):
        result = run("cli", args)
        assert result == {"code": 0, "heavy": []}, (args, result)
