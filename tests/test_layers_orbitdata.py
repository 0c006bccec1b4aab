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

from pathlib import Path

from layers import Package, _one_cycle, strongly_connected

import orbitdata

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
ORBITDATA = Package(Path(orbitdata.__file__).parent, RANK)
imported, unit_of = ORBITDATA.imported, ORBITDATA.unit_of


def test_every_import_points_down_a_layer():
    upward = ORBITDATA.upward_imports()
    assert not upward, "imports that point up or sideways:\n" + "\n".join(upward)


def test_no_import_cycle():
    cycles = ORBITDATA.cycles()
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


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
    assert [_one_cycle(graph, group) for group in strongly_connected(graph)] == [["a", "b", "c", "a"]]
    assert strongly_connected({"a": {"b"}, "b": set()}) == []
