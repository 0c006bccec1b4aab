"""A grid flight's finished chunks, kept beside its table as they land, so that a flight cut short
(killed, out of time) takes up where it stopped when the same command runs again.

``eval closed-loop --json OUT.json`` appends every finished chunk (``lockstep.chunks``: the unit
of work, here and on Ray) to ``OUT.chunks.jsonl``: its episodes, their latencies and the chunk's
phase timings. The file's first line names the flight (:func:`flight_key`): the request, the
chunks it splits into, the run's weights, the code and the kernels. Run again with the same key,
the flight flies only the chunks the file lacks; which episodes share a batch depends only on the
grid and the batch size, so the table is the one an uncut flight writes (its latencies are those
measured when each chunk flew). A file with another key (a changed flag, a retrained run, changed
code) is replaced by the new flight's once its first chunk lands. The file goes once the table is
written. While a flight runs it holds ``OUT.json.lock`` (:func:`flight_lock`): a second flight to the
same table is refused, not left to rewrite the first one's chunks.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import hashlib
import importlib.util
import json
import os
from pathlib import Path

import torch

from orbitmodel.evaluate.lockstep import ChunkResult, FlownEpisode

# What a pilot loads from a run folder: weights and their cards, the probe chosen on validation,
# and the pointer to the checkpoint a run without final weights is flown from.
WEIGHT_FILES = ("*.safetensors", "config.json", "latent_probe.json", "latest")
SKIPPED = {"tensorboard"}
RECORD_KEYS = ("obstacles", "speed", "episode", "outcome")  # what landing an episode reads


def chunk_log_path(report: Path) -> Path:
    """``OUT.chunks.jsonl`` for the table ``OUT.json``."""
    return report.with_suffix(".chunks.jsonl")


@contextlib.contextmanager
def flight_lock(report: Path):
    """Hold ``OUT.json.lock`` (an advisory lock, with this process's id in it) for ``OUT.json``'s flight:
    raises FileExistsError naming the holder's id while another flight holds it. The file goes
    when the flight ends; the lock goes with the process, however it ends."""
    path = Path(report).with_name(Path(report).name + ".lock")  # never the table's own name
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise FileExistsError(
                f"{report}: another flight (process {holder}) is flying this table now; wait for it to end, "
                "or give another --json"
            ) from None
        try:
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                break
        except FileNotFoundError:
            pass
        os.close(fd)  # the flight that held it removed the file before this lock landed: take a new one
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    try:
        yield
    finally:
        path.unlink(missing_ok=True)  # while still held, so no waiting flight locks a removed file
        os.close(fd)


def weights_state(run: Path | None) -> list[tuple[str, int, int]]:
    """(path in the run, size, modification time in ns) of every file a pilot can load from
    ``run``: a retrained or refitted part changes it."""
    if run is None or not Path(run).is_dir():
        return []
    run = Path(run)
    found = []
    for path in run.rglob("*"):
        parts = path.relative_to(run).parts
        if not any(path.match(pattern) for pattern in WEIGHT_FILES) or SKIPPED.intersection(parts[:-1]):
            continue
        if not path.is_file() or ("checkpoints" in parts[:-1] and path.name != "latest"):
            continue  # a checkpoint flown is named by its pointer, which a new checkpoint rewrites
        stat = path.stat()
        found.append((path.relative_to(run).as_posix(), stat.st_size, stat.st_mtime_ns))
    return sorted(found)


def code_state() -> str:
    """sha256 of orbitdata's and orbitmodel's sources: changed code flies another flight."""
    h = hashlib.sha256()
    for package in ("orbitdata", "orbitmodel"):
        root = Path(importlib.util.find_spec(package).submodule_search_locations[0])
        for path in sorted(root.rglob("*.py")):
            h.update(path.relative_to(root).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def flight_key(req, run: Path | None, parts: list[range]) -> str:
    """What makes two flights one: the request (wherever its chunks fly: a Ray grid is the local
    grid), the run it reads and the state of its weights, the chunks, the code, and the kernels
    and threads its sums run on."""
    video = None if req.video_dir is None else Path(req.video_dir).resolve()
    request = dataclasses.replace(
        req, run=None if run is None else Path(run).resolve(), executor="local", ray_address=None, video_dir=video
    )
    text = json.dumps(
        {
            "request": repr(request),
            "weights": weights_state(run),
            "chunks": [[p.start, p.stop] for p in parts],
            "code": code_state(),
            "torch": torch.__version__,
            "kernels": torch.backends.cpu.get_cpu_capability(),
            "threads": torch.get_num_threads(),
        }
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
    if len(episodes) != stop - start or any(k not in e.record for e in episodes for k in RECORD_KEYS):
        raise ValueError(f"chunk [{start}, {stop}) is not whole")
    return ChunkResult(range(start, stop), episodes, dict(entry["timings"]))


class ChunkLog:
    """The chunks of the flight ``key`` kept in ``path``: :meth:`resume` reads those a cut flight
    left, :meth:`add` appends one as it lands (written through to the disk; the first one writes
    the file afresh, with the kept chunks), :meth:`remove` deletes the file once the table is
    written. A file of another flight stays until this flight's first chunk lands."""

    def __init__(self, path: Path, key: str):
        self.path, self.key = Path(path), key
        self.replaced = False  # the file held another flight's chunks (set by resume)
        self._kept: dict[int, ChunkResult] = {}
        self._file = None

    def resume(self, parts: list[range]) -> dict[int, ChunkResult]:
        """The chunks of ``parts`` a cut flight of this key left, by their first episode, which
        the file keeps when the next chunk lands (:meth:`add`)."""
        self._kept = self._read(parts)
        return self._kept

    def _read(self, parts: list[range]) -> dict[int, ChunkResult]:
        """The kept chunks; empty for a file of another flight or none. A line the kill cut
        short ends the reading."""
        if not self.path.is_file():
            return {}
        try:
            lines = self.path.read_text().splitlines()
            self.replaced = not lines or json.loads(lines[0]).get("key") != self.key
        except (UnicodeDecodeError, json.JSONDecodeError, AttributeError):
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

    def _start(self, kept: dict[int, ChunkResult]) -> None:
        """Write the file afresh: this flight's key and the chunks ``kept`` (a cut line dropped)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        with tmp.open("w") as f:
            f.write(json.dumps({"key": self.key}) + "\n")
            for start in sorted(kept):
                f.write(json.dumps(_entry(kept[start])) + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        self._file = self.path.open("a")

    def add(self, chunk: ChunkResult) -> None:
        """Append a finished chunk, on the disk before this returns."""
        if self._file is None:
            self._start(self._kept)
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
