"""orbitdata's layers import one way, in the order of the pipeline (``docs/design.md``, "One-way layers"):

    version, lazy, schema, seeding, cards  <-  state, codecs  <-  scenario  <-  sim  <-  fly  <-  config
    <-  info  <-  load.source, load.rows  <-  write  <-  validate  <-  publish  <-  load  <-  viz  <-  cli
    <-  the package's lazy facade (orbitdata/__init__.py) and ``python -m orbitdata`` (__main__.py)

``config`` sits above ``fly``: ``GenerationConfig`` nests the scenario, simulator and pilot
settings, while flying takes only those sections (``fly.config.FlightConfig``). The dataset
reader that ``write`` (resume, re-shard), ``validate`` and ``publish`` use, ``load/source.py``
(where a dataset is, its meta files) and ``load/rows.py`` (rows of a Parquet file), sits under
them; the rest of ``load`` (tables, windows, episodes) is the pipeline's last stage.

A module may import its own unit and any unit below it, never one above or beside it. Every
import counts: top-level, inside functions (lazy), and module paths spelt as strings for
``importlib`` (lazy tables). And no import cycle, inside a unit either.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import orbitdata

ROOT = Path(orbitdata.__file__).parent
RANK = {
    "version": 0,
    "lazy": 0,
    "schema": 0,
    "seeding": 0,
    "cards": 0,
    "state": 1,
    "codecs": 1,
    "scenario": 2,
    "sim": 3,
    "fly": 4,
    "config": 5,
    "info": 6,
    "load.source": 7,
    "load.rows": 7,
    "write": 8,
    "validate": 9,
    "publish": 10,
    "load": 11,
    "viz": 12,
    "cli": 13,
    "__main__": 14,
    "__init__": 14,
}
MODULE_PATH = re.compile(r"^orbitdata(\.\w+)+$")


def unit_of(module: str) -> str:
    """'orbitdata.fly.grid' -> 'fly'; 'orbitdata.load.source' -> 'load.source'; 'orbitdata' -> '__init__'."""
    parts = module.split(".")[1:]
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in RANK:
            return ".".join(parts[:n])
    return parts[0] if parts else "__init__"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def is_module(name: str) -> bool:
    """True if ``name`` is a module or a package of orbitdata."""
    path = ROOT.parent.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def imported(path: Path, name: str | None = None) -> list[tuple[int, str]]:
    """(line, module) of every orbitdata module ``path`` (module ``name``) imports, however it imports it."""
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
            # from orbitdata.write import parts: the module parts; from orbitdata.load import read_info: the package
            out += [(node.lineno, f"{base}.{a.name}" if is_module(f"{base}.{a.name}") else base) for a in node.names]
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and MODULE_PATH.match(node.value)
            and is_module(node.value)
        ):  # an entry point group such as "orbitdata.pilots" is no module
            out.append((node.lineno, node.value))
    return sorted({(line, m) for line, m in out if m == "orbitdata" or m.startswith("orbitdata.")})


def import_graph() -> dict[str, set[str]]:
    graph = {}
    for path in sorted(ROOT.rglob("*.py")):
        name = module_name(path)
        graph[name] = {m for _, m in imported(path, name) if m != name}
    return graph


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """For each group of modules that import each other in a circle (a strongly connected
    component): one shortest cycle through its first module, the first repeated at the end."""
    index, low, stack, on_stack, groups = {}, {}, [], set(), []

    def visit(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while not group or group[-1] != v:
                group.append(stack.pop())
                on_stack.discard(group[-1])
            if len(group) > 1:
                groups.append(set(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_one_cycle(graph, group) for group in groups]


def _one_cycle(graph: dict[str, set[str]], group: set[str]) -> list[str]:
    start = min(group)
    paths, seen = {start: [start]}, {start}
    frontier = [start]
    while frontier:  # breadth first, inside the group, back to the start
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & group):
                if w == start:
                    return paths[v] + [start]
                if w not in seen:
                    seen.add(w)
                    paths[w] = paths[v] + [w]
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no cycle through {start} in {sorted(group)}")


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


def test_no_import_cycle():
    graph = import_graph()
    cycles = find_cycles(graph)
    # Every module of a group that a cycle goes through, so that one report shows the whole tangle.
    within = [sorted(m for m in graph if _reaches(graph, m, c[0]) and _reaches(graph, c[0], m)) for c in cycles]
    assert not cycles, "import cycles:\n" + "\n".join(
        f"{' -> '.join(c)} (the circle holds {', '.join(group)})" for c, group in zip(cycles, within)
    )


def _reaches(graph: dict[str, set[str]], a: str, b: str) -> bool:
    seen, todo = {a}, [a]
    while todo:
        for w in graph.get(todo.pop(), ()):
            if w == b:
                return True
            if w not in seen:
                seen.add(w)
                todo.append(w)
    return a == b


def test_the_check_sees_lazy_relative_and_string_imports(tmp_path):
    """The scanner itself: a function-level import, a relative one, a submodule named in a
    ``from`` import and an importlib path in a table all count (a file standing in for a module of
    the fly package); a dotted string that names no module does not."""
    example = tmp_path / "example.py"
    example.write_text(
        "def f():\n    from orbitdata.write.generate import generate\n\n"
        "from ..load import source\nfrom orbitdata import schema as S\n"
        'TABLE = {"x": "orbitdata.viz.overview", "group": "orbitdata.pilots"}\n'
    )
    found = [m for _, m in imported(example, "orbitdata.fly.example")]
    assert sorted(found) == [
        "orbitdata.load.source",
        "orbitdata.schema",
        "orbitdata.viz.overview",
        "orbitdata.write.generate",
    ]
    assert unit_of("orbitdata.load.source") == "load.source" and unit_of("orbitdata.load.windows") == "load"


def test_the_cycle_check_finds_a_cycle_through_a_lazy_import():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}}
    assert find_cycles(graph) == [["a", "b", "c", "a"]]
    assert find_cycles({"a": {"b"}, "b": set()}) == []
