"""A grid flight's finished chunks, kept beside its table as they land, so that a flight cut short
(killed, out of time) takes up where it stopped when the same command runs again.

``eval closed-loop --json OUT.json`` appends every finished chunk (``lockstep.chunks``: the unit
of work, here and on Ray) to ``OUT.chunks.jsonl``: its episodes, their latencies and the chunk's
phase timings. The file's first line names the flight (:func:`flight_key`): the request, the
chunks it splits into and the run's weights. Run again with the same key, the flight flies only
the chunks the file lacks; which episodes share a batch depends only on the grid and the batch
size, so the table is the one an uncut flight writes (its latencies are those measured when each
chunk flew). A file with another key (a changed flag, a retrained run) is replaced by the new
flight's. The file goes once the table is written.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

from orbitmodel.evaluate.lockstep import ChunkResult, FlownEpisode

WEIGHT_FILES = ("*.safetensors", "config.json", "latent_probe.json")  # what a pilot loads from a run folder
SKIPPED = {"checkpoints", "tensorboard"}  # training state, not the weights flown


def chunk_log_path(report: Path) -> Path:
    """``OUT.chunks.jsonl`` for the table ``OUT.json``."""
    return report.with_suffix(".chunks.jsonl")


def weights_state(run: Path | None) -> list[tuple[str, int, int]]:
    """(path in the run, size, modification time in ns) of every file a pilot can load from
    ``run``: a retrained or refitted part changes it."""
    if run is None or not Path(run).is_dir():
        return []
    run = Path(run)
    found = []
    for pattern in WEIGHT_FILES:
        for path in run.rglob(pattern):
            parts = path.relative_to(run).parts
            if SKIPPED.intersection(parts[:-1]) or not path.is_file():
                continue
            stat = path.stat()
            found.append((path.relative_to(run).as_posix(), stat.st_size, stat.st_mtime_ns))
    return sorted(found)


def flight_key(req, run: Path | None, parts: list[range]) -> str:
    """What makes two flights one: the request (wherever its chunks fly: a Ray grid is the local
    grid), the run it reads and the state of its weights, and the chunks."""
    request = dataclasses.replace(req, run=None if run is None else Path(run).resolve(), executor="local")
    text = json.dumps(
        {"request": repr(request), "weights": weights_state(run), "chunks": [[p.start, p.stop] for p in parts]}
    )
    return hashlib.sha256(text.encode()).hexdigest()


def _entry(chunk: ChunkResult) -> dict:
    return {
        "chunk": [chunk.part.start, chunk.part.stop],
        "episodes": [dataclasses.asdict(e) for e in chunk.episodes],
        "timings": chunk.timings,
    }


def _chunk(entry: dict) -> ChunkResult:
    start, stop = entry["chunk"]
    episodes = [FlownEpisode(**e) for e in entry["episodes"]]
    return ChunkResult(range(start, stop), episodes, dict(entry["timings"]))


class ChunkLog:
    """The chunks of the flight ``key`` kept in ``path``: :meth:`resume` reads those a cut flight
    left and opens the file for more, :meth:`add` appends one as it lands (written through to the
    disk), :meth:`remove` deletes the file once the table is written."""

    def __init__(self, path: Path, key: str):
        self.path, self.key = Path(path), key
        self.replaced = False  # the file held another flight's chunks (set by kept)
        self._file = None

    def resume(self, parts: list[range]) -> dict[int, ChunkResult]:
        """The chunks of ``parts`` a cut flight of this key left (:meth:`kept`); the file is then
        written afresh with them (:meth:`start`), open for the chunks still to fly."""
        kept = self.kept(parts)
        self.start(kept)
        return kept

    def kept(self, parts: list[range]) -> dict[int, ChunkResult]:
        """The chunks of this flight already flown, by their first episode; empty for a file of
        another flight or none. A line the kill cut short ends the reading."""
        if not self.path.is_file():
            return {}
        lines = self.path.read_text().splitlines()
        try:
            self.replaced = not lines or json.loads(lines[0]).get("key") != self.key
        except (json.JSONDecodeError, AttributeError):
            self.replaced = True
        if self.replaced:
            return {}
        wanted = {(p.start, p.stop) for p in parts}
        kept = {}
        for line in lines[1:]:
            try:
                chunk = _chunk(json.loads(line))
            except (json.JSONDecodeError, KeyError, TypeError, ValueError):
                break  # the last line, cut by the kill
            if (chunk.part.start, chunk.part.stop) in wanted:
                kept[chunk.part.start] = chunk
        return kept

    def start(self, kept: dict[int, ChunkResult]) -> None:
        """Write the file afresh: this flight's key and the chunks ``kept`` (a cut line dropped)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        with tmp.open("w") as f:
            f.write(json.dumps({"key": self.key}) + "\n")
            for start in sorted(kept):
                f.write(json.dumps(_entry(kept[start])) + "\n")
        os.replace(tmp, self.path)
        self._file = self.path.open("a")

    def add(self, chunk: ChunkResult) -> None:
        """Append a finished chunk, on the disk before this returns."""
        self._file.write(json.dumps(_entry(chunk)) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def remove(self) -> None:
        self.close()
        self.path.unlink(missing_ok=True)
