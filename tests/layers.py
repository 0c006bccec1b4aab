"""The import scanner behind the layer tests of both packages (``test_layers_orbitdata.py``,
``model/test_layers.py``): every import a module makes, however it makes it (top-level, inside a
function, relative, or a module path spelt as a string for ``importlib``), the import graph, the
imports that point up or sideways, and the cycles."""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Package:
    """A package's folder and its layers: ``rank`` maps a unit (a top-level module or
    sub-package, or a dotted module inside one, e.g. ``load.source``) to its layer."""

    root: Path
    rank: dict[str, int]

    @property
    def name(self) -> str:
        return self.root.name

    def unit_of(self, module: str) -> str:
        """'pkg.fly.grid' -> 'fly'; 'pkg.load.source' -> 'load.source' when ranked; 'pkg' -> '__init__'."""
        parts = module.split(".")[1:]
        for n in range(len(parts), 0, -1):
            if ".".join(parts[:n]) in self.rank:
                return ".".join(parts[:n])
        return parts[0] if parts else "__init__"

    def module_name(self, path: Path) -> str:
        parts = list(path.relative_to(self.root.parent).with_suffix("").parts)
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    def is_module(self, name: str) -> bool:
        """True if ``name`` is a module or a package of this package."""
        path = self.root.parent.joinpath(*name.split("."))
        return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()

    def imported(self, path: Path, name: str | None = None) -> list[tuple[int, str]]:
        """(line, module) of every module of this package that ``path`` (module ``name``) imports."""
        name = name or self.module_name(path)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        string_path = re.compile(rf"^{self.name}(\.\w+)+$")
        out = []
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                out += [(node.lineno, a.name) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:  # relative: resolve against this module's package
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                # from pkg.write import parts: the module parts; from pkg.load import read_info: the package
                out += [
                    (node.lineno, f"{base}.{a.name}" if self.is_module(f"{base}.{a.name}") else base)
                    for a in node.names
                ]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str) and string_path.match(node.value):
                if self.is_module(node.value):  # an entry point group such as "orbitdata.pilots" is no module
                    out.append((node.lineno, node.value))
        return sorted({(line, m) for line, m in out if m == self.name or m.startswith(self.name + ".")})

    def files(self) -> list[Path]:
        return sorted(self.root.rglob("*.py"))

    def upward_imports(self) -> list[str]:
        """Every import that points up or sideways, as 'file:line (unit) imports module (unit)'."""
        upward = []
        for path in self.files():
            source = self.unit_of(self.module_name(path))
            assert source in self.rank, f"{path}: a new top-level unit {source!r}; give it a layer in RANK"
            for line, module in self.imported(path):
                target = self.unit_of(module)
                assert target in self.rank, f"{path}:{line} imports {module}, which is in no layer"
                if target != source and self.rank[target] >= self.rank[source]:
                    upward.append(f"{path.relative_to(self.root.parent)}:{line} ({source}) imports {module} ({target})")
        return upward

    def import_graph(self) -> dict[str, set[str]]:
        graph = {}
        for path in self.files():
            name = self.module_name(path)
            graph[name] = {m for _, m in self.imported(path, name) if m != name}
        return graph

    def cycles(self) -> list[str]:
        """One line per group of modules that import each other in a circle: a shortest cycle and
        every module of the group."""
        graph = self.import_graph()
        return [
            f"{' -> '.join(_one_cycle(graph, group))} (the circle holds {', '.join(sorted(group))})"
            for group in strongly_connected(graph)
        ]


def strongly_connected(graph: dict[str, set[str]]) -> list[set[str]]:
    """The groups of two or more nodes that reach each other (Tarjan's algorithm)."""
    index, low, stack, on_stack, groups = {}, {}, [], set(), []

    def visit(v: str) -> None:
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
    return groups


def _one_cycle(graph: dict[str, set[str]], group: set[str]) -> list[str]:
    start = min(group)
    paths, seen, frontier = {start: [start]}, {start}, [start]
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
