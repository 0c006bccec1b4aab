"""``meta/info.json`` as a typed object: what a dataset is and how it was made.

The writer builds an :class:`Info` and writes :meth:`Info.to_dict`; every reader (the loader,
``orbitdata info``, ``push``, ``generate`` when it resumes) gets one from
:func:`orbitdata.load.read_info` or :func:`orbitdata.load.read_meta`. The validator reads the
raw JSON, since it must report a broken file rather than stop at it, but checks it against the
same rules (:func:`counts`, :func:`orbitdata.schema.readable_schema`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Iterable

from orbitdata import schema as S


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file's bytes (what info.json records for every file)."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


@dataclass(frozen=True)
class FileEntry:
    sha256: str  # hex digest
    bytes: int

    @classmethod
    def of(cls, path: Path) -> "FileEntry":
        return cls(sha256_file(path), Path(path).stat().st_size)


@dataclass(frozen=True)
class Info:
    """The fields of ``meta/info.json``.

    Attributes:
        schema_version: the layout and columns (``orbitdata.schema.SCHEMA_VERSION`` when written).
        codebase_version: "orbitdata X.Y.Z" that wrote it.
        fps, dt: control rate (25 Hz) and step (0.04 s).
        root_seed: the generation's root seed.
        counts: episodes and frames, per split, level and outcome (see :func:`counts`).
        features: per column: dtype, shape, codec, unit (e.g. depth ``range_m`` = [near, far]).
        storage: Parquet compression, rows per row group, data-shard size limit.
        hardware: thruster layout and wrench matrix.
        config: ``GenerationConfig.to_dict()``: every setting that made the dataset.
        files: every other file of the dataset -> sha256 and size.
    """

    schema_version: str
    codebase_version: str
    fps: int
    dt: float
    root_seed: int
    counts: dict
    features: dict
    storage: dict
    hardware: dict
    config: dict
    files: dict[str, FileEntry] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: dict, where: str = S.INFO_PATH) -> "Info":
        """Check and type a parsed info.json; ValueError names what is wrong and where."""
        if not isinstance(data, dict):
            raise ValueError(f"{where} is not a JSON object; run `orbitdata validate` on the dataset")
        version = data.get("schema_version")
        if version is None:
            raise ValueError(f"{where} has no schema_version; it was not written by orbitdata")
        if not isinstance(version, str):
            raise ValueError(f"{where}: schema_version must be a string like {S.SCHEMA_VERSION!r}, not {version!r}")
        if not S.readable_schema(version):
            from orbitdata.version import __version__

            raise ValueError(
                f"{where}: the dataset has schema version {version!r}, but orbitdata {__version__} reads "
                f"schema {S.SCHEMA_VERSION.split('.')[0]}.x; install the orbitdata release that matches "
                "the dataset"
            )
        problems = cls.field_problems(data)
        if problems:
            raise ValueError(f"{where} {'; '.join(problems)}; run `orbitdata validate` on the dataset")
        try:
            files = {rel: FileEntry(str(e["sha256"]), int(e["bytes"])) for rel, e in data["files"].items()}
        except (AttributeError, KeyError, TypeError, ValueError):
            raise ValueError(
                f"{where}: 'files' must map each path to its sha256 and bytes; run `orbitdata validate` on the dataset"
            ) from None
        return cls(**{f.name: data[f.name] for f in fields(cls) if f.name != "files"}, files=files)

    @classmethod
    def field_problems(cls, data: dict) -> list[str]:
        """What keeps ``data`` from being an info.json's fields: those missing, and those of the
        wrong kind (``files`` is :meth:`from_dict`'s to check)."""
        kinds = {"str": (str, "a string"), "int": (int, "a whole number"), "float": ((int, float), "a number")}
        kinds["dict"] = (dict, "a JSON object")
        missing = [f.name for f in fields(cls) if f.name not in data]
        out = [f"lacks {', '.join(missing)}"] if missing else []
        for f in fields(cls):
            if f.name in data and f.type in kinds:
                value, (kind, name) = data[f.name], kinds[f.type]
                if isinstance(value, bool) or not isinstance(value, kind):
                    out.append(f"{f.name} must be {name}, not {json.dumps(value)[:40]}")
        return out

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["files"] = {rel: {"sha256": e.sha256, "bytes": e.bytes} for rel, e in self.files.items()}
        return out

    @property
    def image_size(self) -> int | None:
        """Side of the square camera images in pixels, from the recorded config."""
        return ((self.config.get("sim") or {}).get("camera") or {}).get("image_size")

    @property
    def tier(self) -> str:
        """The scenario tier, from the recorded config (a static record leaves it out)."""
        return (self.config.get("scenario") or {}).get("tier", S.STATIC_TIER)

    @property
    def max_steps(self) -> int | None:
        """Frames per episode at most."""
        return (self.config.get("sim") or {}).get("max_steps")

    @property
    def bytes(self) -> int:
        """Size of the files info.json lists (every file but info.json itself)."""
        return sum(e.bytes for e in self.files.values())

    def generation_config(self):
        """The :class:`~orbitdata.config.GenerationConfig` that made the dataset."""
        from orbitdata.config import GenerationConfig

        return GenerationConfig.from_dict(self.config, where=f"{S.INFO_PATH} config")


def counts(rows: Iterable[tuple[str, str, str, int]], tier: str = S.STATIC_TIER) -> dict:
    """Episode and frame counts per split, level and outcome from ``(split, level, outcome, length)`` rows.

    The definition of info.json's ``counts``: the writer states it, the validator recomputes it.
    The outcomes counted are the ``tier``'s (``orbitdata.schema.outcomes``).
    """
    rows = list(rows)
    names = S.outcomes(tier)

    def tally(mine: list) -> dict:
        return {o: sum(1 for r in mine if r[2] == o) for o in names}

    out: dict = {"episodes": len(rows), "frames": sum(r[3] for r in rows), "splits": {}}
    for split in S.SPLITS:
        mine = [r for r in rows if r[0] == split]
        if not mine:
            continue
        levels = {}
        for level in S.LEVELS:
            lv = [r for r in mine if r[1] == level]
            levels[level] = {"episodes": len(lv), "frames": sum(r[3] for r in lv), "outcomes": tally(lv)}
        out["splits"][split] = {
            "episodes": len(mine),
            "frames": sum(r[3] for r in mine),
            "levels": levels,
            "outcomes": tally(mine),
        }
    return out
