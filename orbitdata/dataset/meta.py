"""``meta/info.json`` and ``meta/stats.json``: what a dataset is and how it was made."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pyarrow as pa

from orbitdata import __version__, schema as S
from orbitdata.config import GenerationConfig
from orbitdata.dataset.encode import PNG_FILTER
from orbitdata.dataset.parts import atomic_write
from orbitdata.sim.thrusters import thruster_layout, wrench_matrix


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def dumps(obj) -> bytes:
    return (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode()


def counts(episodes: pa.Table) -> dict:
    """Episode and frame counts per split, level and outcome."""
    rows = episodes.select([S.SPLIT, S.LEVEL, S.OUTCOME, S.LENGTH]).to_pylist()
    out: dict = {"episodes": len(rows), "frames": sum(r[S.LENGTH] for r in rows), "splits": {}}
    for split in S.SPLITS:
        mine = [r for r in rows if r[S.SPLIT] == split]
        if not mine:
            continue
        levels = {}
        for level in S.LEVELS:
            lv = [r for r in mine if r[S.LEVEL] == level]
            levels[level] = {
                "episodes": len(lv),
                "frames": sum(r[S.LENGTH] for r in lv),
                "outcomes": {o: sum(1 for r in lv if r[S.OUTCOME] == o) for o in S.OUTCOMES},
            }
        out["splits"][split] = {
            "episodes": len(mine),
            "frames": sum(r[S.LENGTH] for r in mine),
            "levels": levels,
            "outcomes": {o: sum(1 for r in mine if r[S.OUTCOME] == o) for o in S.OUTCOMES},
        }
    return out


def hardware(config: GenerationConfig) -> dict:
    """Thruster geometry and wrench facts, recorded with every dataset."""
    pos, dirs = thruster_layout(config.sim.cubesat)
    W = wrench_matrix(config.sim.cubesat)
    return {
        "thruster_positions_m": np.round(pos, 6).tolist(),
        "thruster_force_directions": np.round(dirs, 6).tolist(),
        "wrench_matrix": np.round(W, 6).tolist(),
        "wrench_rank": int(np.linalg.matrix_rank(W)),
        "frames": "world: inertial, origin at the start; body: +x camera axis, +z image up",
    }


def build_info(config: GenerationConfig, episodes: pa.Table, out: Path, files: list[str]) -> dict:
    ds = config.dataset
    size = config.sim.camera.image_size
    return {
        "schema_version": S.SCHEMA_VERSION,
        "codebase_version": f"orbitdata {__version__}",
        "fps": S.FPS,
        "dt": S.DT,
        "root_seed": ds.seed,
        "counts": counts(episodes),
        "features": {
            S.IMAGE: {"dtype": "image", "shape": [size, size, 3], "codec": "jpeg", "quality": ds.jpeg_quality},
            S.DEPTH: {
                "dtype": "image",
                "shape": [size, size],
                "codec": "png16",
                "png_filter": PNG_FILTER,
                "png_compression": ds.png_compression,
                "unit": "mm",
                "no_return": 0,
                "range_m": [config.sim.camera.near, config.sim.camera.far],
            },
            S.DEPTH_LOW: {"dtype": "float32", "shape": [S.DEPTH_LOW_SIDE, S.DEPTH_LOW_SIDE], "unit": "m"},
            S.STATE: {"dtype": "float32", "shape": [S.STATE_DIM], "names": list(S.STATE_NAMES)},
            S.ACTION: {"dtype": "float32", "shape": [S.ACTION_DIM], "names": [f"thruster_{i}" for i in range(8)]},
            S.MIN_CLEARANCE: {"dtype": "float32", "shape": [1], "unit": "m"},
        },
        "storage": {
            "compression": ds.compression,
            "row_group_rows": ds.row_group_rows,
            "max_shard_bytes": ds.max_shard_bytes,
        },
        "hardware": hardware(config),
        "config": config.to_dict(),
        "files": {rel: {"sha256": sha256_file(out / rel), "bytes": (out / rel).stat().st_size} for rel in sorted(files)},
    }


def write_json(out: Path, rel: str, obj) -> None:
    atomic_write(out / rel, dumps(obj))
