"""Part files: the crash-safe scratch layout that `generate` fills and `shard` compacts.

    OUT/parts/manifest.json                   the effective config of this generation
    OUT/parts/unit-00042.steps.parquet        frames of unit 42
    OUT/parts/unit-00042.episodes.parquet     its episode rows, written last: a unit is done
                                              iff this file exists

Every file is written to a hidden temporary name in the same folder, fsynced and renamed,
so a kill at any moment leaves either the whole file or nothing under its final name.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from orbitdata.schema import PARTS_DIR

MANIFEST_FILE = "manifest.json"


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` whole or not at all; a failed write (a full disk) leaves no
    temporary behind and names ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".tmp-{os.getpid()}-{path.name}")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename is None:  # a write's error names no file
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise


def write_report(path: Path, text: str) -> None:
    """Write a report at the end of a command: a file whole or not at all (an interrupted write
    leaves the old one), or a stream or device such as ``/dev/stdout`` as it is."""
    if path.exists() and not path.is_file():
        path.write_text(text)
    else:
        atomic_write(path, text.encode())


def parts_dir(out: Path) -> Path:
    return out / PARTS_DIR


def steps_part(out: Path, unit_name: str) -> Path:
    return parts_dir(out) / f"{unit_name}.steps.parquet"


def episodes_part(out: Path, unit_name: str) -> Path:
    return parts_dir(out) / f"{unit_name}.episodes.parquet"


def is_done(out: Path, unit_name: str) -> bool:
    return episodes_part(out, unit_name).exists() and steps_part(out, unit_name).exists()


def drop_damaged(out: Path, unit_names: list[str]) -> list[Path]:
    """Remove the parts of every finished unit whose files Parquet cannot open (a copy cut short,
    a disk error: the atomic writes above never leave one), so that generating again redoes those
    units. Returns the damaged files."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    bad = []
    for name in unit_names:
        files = (steps_part(out, name), episodes_part(out, name))
        for f in files:
            try:
                pq.read_metadata(f)
            except (pa.ArrowException, OSError) as exc:
                if isinstance(exc, PermissionError):
                    raise
                bad.append(f)
        if any(f in bad for f in files):
            for f in (episodes_part(out, name), steps_part(out, name)):  # the mark of a finished unit first
                f.unlink(missing_ok=True)
    return bad


def write_unit(out: Path, unit_name: str, steps: bytes, episodes: bytes) -> None:
    atomic_write(steps_part(out, unit_name), steps)
    atomic_write(episodes_part(out, unit_name), episodes)  # last: marks the unit done


def remove_temporaries(folder: Path) -> None:
    """Delete leftovers of writes that were killed before their rename."""
    if folder.is_dir():
        for tmp in folder.glob(".tmp-*"):
            tmp.unlink(missing_ok=True)


def read_manifest(out: Path) -> dict | None:
    path = parts_dir(out) / MANIFEST_FILE
    if not path.exists():
        return None
    return json.loads(path.read_text())


def write_manifest(out: Path, manifest: dict) -> None:
    atomic_write(parts_dir(out) / MANIFEST_FILE, json.dumps(manifest, indent=2, sort_keys=True).encode())
