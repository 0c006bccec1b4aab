"""orbitmodel's layers import one way (``shared/DESIGN.md``, "Layers of orbitmodel"):

    loop_settings  <-  config, data, extras, kinematics  <-  runs  <-  model  <-  train  <-  probe | baselines
    <-  plan  <-  evaluate  <-  publish  <-  cli  <-  the package's lazy facade (orbitmodel/__init__.py)

A module may import its own unit and any unit below it, never one above or beside it (probe and
baselines are siblings). Every import counts: top-level, inside functions (lazy), and module
paths spelt as strings for ``importlib`` (lazy tables). And orbitdata never imports orbitmodel.
"""

from __future__ import annotations

import ast
from pathlib import Path

from layers import Package

import orbitdata
import orbitmodel

RANK = {
    "loop_settings": 0,
    "config": 1,
    "data": 1,
    "extras": 1,
    "kinematics": 1,
    "runs": 2,
    "model": 3,
    "train": 4,
    "probe": 5,
    "baselines": 5,
    "plan": 6,
    "evaluate": 7,
    "publish": 8,
    "cli": 9,
    "__init__": 10,
}
ORBITMODEL = Package(Path(orbitmodel.__file__).parent, RANK)
imported = ORBITMODEL.imported


def test_every_import_points_down_a_layer():
    upward = ORBITMODEL.upward_imports()
    assert not upward, "imports that point up or sideways:\n" + "\n".join(upward)


def test_no_import_cycle():
    """Inside a layer too: the units' order allows a module to import its own unit, so a circle
    between two modules of one unit is caught here."""
    cycles = ORBITMODEL.cycles()
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_the_check_sees_lazy_relative_and_string_imports(tmp_path):
    """The scanner itself: a function-level import, a relative one and an importlib path in a
    table all count (a file standing in for a module of the probe package)."""
    example = tmp_path / "example.py"
    example.write_text(
        "def f():\n    from orbitmodel.plan.cost import CostConfig\n\n"
        'from ..evaluate import rollout\nTABLE = {"x": "orbitmodel.evaluate.figure6"}\n'
    )
    found = [m for _, m in imported(example, "orbitmodel.probe.example")]
    assert sorted(found) == ["orbitmodel.evaluate.figure6", "orbitmodel.evaluate.rollout", "orbitmodel.plan.cost"]


def test_orbitdata_never_imports_orbitmodel():
    offenders = []
    for path in sorted(Path(orbitdata.__file__).parent.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            offenders += [f"{path}:{node.lineno}" for n in names if n.split(".")[0] == "orbitmodel"]
    assert not offenders, offenders
