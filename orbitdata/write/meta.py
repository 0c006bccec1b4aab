"""Build ``meta/info.json`` (an :class:`~orbitdata.info.Info`): what a dataset is and how it was made; and
read back the repo id the card loads from."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.codecs import PNG_FILTER
from orbitdata.config import GenerationConfig
from orbitdata.info import FileEntry, Info, counts
from orbitdata.scenario.config import STATIC
from orbitdata.sim.thrusters import thruster_layout, wrench_matrix
from orbitdata.state import STATE_NAMES
from orbitdata.version import __version__
from orbitdata.write.parts import atomic_write


def dumps(obj) -> bytes:
    return (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode()


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


def _unit(name: str, tier: str = STATIC) -> str:
    return next(f.unit for f in S.step_fields(tier) if f.name == name)


def _tier_features(tier: str) -> dict:
    """The features a tier adds to the static ones (none for the static tier)."""
    if tier == STATIC:
        return {}
    return {
        S.OBSTACLE_POSES: {
            "dtype": "float32",
            "shape": [S.N_OBSTACLES, 7],  # per frame: one row per obstacle of the episode
            "names": ["x", "y", "z", "qw", "qx", "qy", "qz"],
            "unit": _unit(S.OBSTACLE_POSES, tier),
            "privileged": True,
        }
    }


def build_info(config: GenerationConfig, episodes: pa.Table, out: Path, files: list[str]) -> Info:
    ds = config.dataset
    size = config.sim.camera.image_size
    rows = zip(*(episodes.column(c).to_pylist() for c in (S.SPLIT, S.LEVEL, S.OUTCOME, S.LENGTH)))
    return Info(
        schema_version=S.SCHEMA_VERSION,
        codebase_version=f"orbitdata {__version__}",
        fps=S.FPS,
        dt=S.DT,
        root_seed=ds.seed,
        counts=counts(rows, config.tier),
        features={
            S.IMAGE: {"dtype": "image", "shape": [size, size, 3], "codec": "jpeg", "quality": ds.jpeg_quality},
            S.DEPTH: {
                "dtype": "image",
                "shape": [size, size],
                "codec": "png16",
                "png_filter": PNG_FILTER,
                "png_compression": ds.png_compression,
                "unit": _unit(S.DEPTH),
                "no_return": 0,
                "range_m": [config.sim.camera.near, config.sim.camera.far],
            },
            S.DEPTH_LOW: {
                "dtype": "float32",
                "shape": [S.DEPTH_LOW_SIDE, S.DEPTH_LOW_SIDE],
                "unit": _unit(S.DEPTH_LOW),
            },
            S.STATE: {"dtype": "float32", "shape": [S.STATE_DIM], "names": list(STATE_NAMES)},
            S.ACTION: {"dtype": "float32", "shape": [S.ACTION_DIM], "names": list(S.ACTION_NAMES)},
            S.MIN_CLEARANCE: {"dtype": "float32", "shape": [1], "unit": _unit(S.MIN_CLEARANCE)},
            **_tier_features(config.tier),
        },
        storage={
            "compression": ds.compression,
            "row_group_rows": ds.row_group_rows,
            "max_shard_bytes": ds.max_shard_bytes,
        },
        hardware=hardware(config),
        config=config.to_dict(),
        files={rel: FileEntry.of(out / rel) for rel in sorted(files)},
    )


def write_json(out: Path, rel: str, obj) -> None:
    atomic_write(out / rel, dumps(obj))


def card_repo(out: Path) -> str | None:
    """The repo id the card in ``out`` loads from (``generate --repo-id``), so re-sharding keeps it."""
    card = out / S.CARD_PATH
    found = (
        re.search(r'^steps = load_dataset\("([^"]+)", split="train"\)', card.read_text(), re.M)
        if card.is_file()
        else None
    )
    return found.group(1) if found else None
