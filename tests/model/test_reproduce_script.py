"""scripts/reproduce_model.sh refuses bad settings in one line, exit 2, before it runs anything, and
never lets the full chain take up a toy-size chain's outputs (nor the other way round)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[2] / "scripts" / "reproduce_model.sh"


def run(out: Path, *args: str, **env: str) -> subprocess.CompletedProcess:
    # BIN points nowhere: a check that let the chain start would fail on a missing program, not exit 2
    environ = {"PATH": os.environ["PATH"], "BIN": str(out / "no-bin"), **env}
    return subprocess.run(["bash", str(SCRIPT), str(out), *args], env=environ, capture_output=True, text=True)


@pytest.mark.parametrize(
    "args, env, named",
    [
        (["abc"], {}, "EPISODES_PER_SETTING=abc"),
        (["0"], {}, "EPISODES_PER_SETTING=0"),
        ([], {"TIER": "dyanmic"}, "TIER=dyanmic"),
        ([], {"TIER": "dynamic", "WAY": "psychic"}, "WAY=psychic"),
        ([], {"POLICY": "no"}, "POLICY=no"),
        ([], {"QUICK": "yes"}, "QUICK=yes"),
        ([], {"BATCH": "0"}, "BATCH=0"),
        ([], {"EXECUTOR": "slurm"}, "EXECUTOR=slurm"),
    ],
)
def test_a_bad_setting_is_refused_before_anything_runs(tmp_path, args, env, named):
    out = tmp_path / "out"
    res = run(out, *args, **env)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and named in res.stderr, res.stderr
    assert not out.exists()  # nothing made


def test_a_folder_holds_one_chains_sizes(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "chain-sizes").write_text("quick\n")  # what a QUICK=1 chain leaves
    full = run(out)
    assert full.returncode == 2 and "holds a chain of quick sizes" in full.stderr and "another OUT" in full.stderr
    assert sorted(p.name for p in out.iterdir()) == ["chain-sizes"]
    (out / "chain-sizes").write_text("full\n")
    quick = run(out, "1", QUICK="1")
    assert quick.returncode == 2 and "holds a chain of full sizes" in quick.stderr
