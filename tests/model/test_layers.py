"""orbitmodel's layers import one way (``shared/DESIGN.md``, "Layers of orbitmodel"):

    loop_settings  <-  config, data, extras, kinematics  <-  runs  <-  model  <-  train  <-  probe | baselines
    <-  plan  <-  evaluate  <-  publish  <-  cli  <-  the package's lazy facade (orbitmodel/__init__.py)

A module may import its own unit and any unit below it, never one above or beside it (probe and
baselines are siblings). Every import counts: top-level, inside functions (lazy), and module
paths spelt as strings for ``importlib`` (lazy tables). And orbitdata never imports orbitmodel.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import orbitdata
import orbitmodel

ROOT = Path(orbitmodel.__file__).parent
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
MODULE_PATH = re.compile(r"^orbitmodel(\.\w+)+$")


def unit_of(module: str) -> str:
    """'orbitmodel.plan.cost' -> 'plan'; 'orbitmodel' -> '__init__' (the facade)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported(path: Path, name: str | None = None) -> list[tuple[int, str]]:
    """(line, module) of every orbitmodel module ``path`` (module ``name``) imports, however it imports it."""
    name = name or module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against this module's package
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            if base == "orbitmodel":  # from orbitmodel import config, WorldModel
                out += [
                    (
                        node.lineno,
                        f"orbitmodel.{a.name}"
                        if (ROOT / a.name).exists() or (ROOT / f"{a.name}.py").exists()
                        else "orbitmodel",
                    )
                    for a in node.names
                ]
            else:
                out.append((node.lineno, base))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and MODULE_PATH.match(node.value):
            out.append((node.lineno, node.value))
    return [(line, m) for line, m in out if m == "orbitmodel" or m.startswith("orbitmodel.")]


def test_every_import_points_down_a_layer():
    upward = []
    for path in sorted(ROOT.rglob("*.py")):
        source = unit_of(module_name(path))
        assert source in RANK, f"{path}: a new top-level unit {source!r}; give it a layer in RANK"
        for line, module in imported(path):
            target = unit_of(module)
            assert target in RANK, f"{path}:{line} imports {module}, which is in no layer"
            if target != source and RANK[target] >= RANK[source]:
                upward.append(f"{path.relative_to(ROOT.parent)}:{line} ({source}) imports {module} ({target})")
    assert not upward, "imports that point up or sideways:\n" + "\n".join(upward)


def test_the_check_sees_lazy_relative_and_string_imports(tmp_path):
    """The scanner itself: a function-level import, a relative one and an importlib path in a
    table all count (a file standing in for a module of the probe package)."""
    example = tmp_path / "example.py"
    example.write_text(
        "def f():\n    from orbitmodel.plan.cost import CostConfig\n\n"
        'from ..evaluate import rollout\nTABLE = {"x": "orbitmodel.evaluate.figure6"}\n'
    )
    found = [m for _, m in imported(example, "orbitmodel.probe.example")]
    assert sorted(found) == ["orbitmodel.evaluate", "orbitmodel.evaluate.figure6", "orbitmodel.plan.cost"]


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
