"""What the model needs from an orbitdata dataset: its metadata (image size, normalisation,
camera) and windows cut through ``orbitdata.load_windows``.

DATASET is a local folder or a Hub repo id, exactly as ``load_windows`` takes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orbitdata import schema as S

LEVEL_CHOICES = S.LEVELS
OUTCOME_CHOICES = S.OUTCOMES


@dataclass(frozen=True)
class DatasetMeta:
    """The facts a model run records about its training data."""

    source: str
    image_size: int
    state_mean: tuple[float, ...]  # (16,)
    state_std: tuple[float, ...]  # (16,)
    action_mean: tuple[float, ...]  # (8,)
    action_std: tuple[float, ...]  # (8,)
    depth_max: float  # metres: the far plane of depth_low
    fovy_deg: float
    root_seed: int
    episodes: dict  # split -> episode count

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, d: dict) -> "DatasetMeta":
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})


def read_dataset_meta(source: str | Path) -> DatasetMeta:
    """Info and stats of an orbitdata dataset; raises FileNotFoundError / ValueError with the fix."""
    from orbitdata.load import read_meta

    info, stats = read_meta(source)
    camera = info.config["sim"]["camera"]
    return DatasetMeta(
        source=str(source),
        image_size=int(info.image_size),
        state_mean=tuple(float(x) for x in stats[S.STATE]["mean"]),
        state_std=tuple(float(x) for x in stats[S.STATE]["std"]),
        action_mean=tuple(float(x) for x in stats[S.ACTION]["mean"]),
        action_std=tuple(float(x) for x in stats[S.ACTION]["std"]),
        depth_max=float(np.max(stats[S.DEPTH_LOW]["max"])),
        fovy_deg=float(camera["fovy_deg"]),
        root_seed=int(info.root_seed),
        episodes={split: int(c["episodes"]) for split, c in info.counts["splits"].items()},
    )


def episode_filter(levels: list[str] | None, outcomes: list[str] | None) -> dict | None:
    """The ``episodes=`` filter of ``load_windows`` for a level / outcome selection."""
    chosen = {}
    if levels:
        chosen[S.LEVEL] = list(levels)
    if outcomes:
        chosen[S.OUTCOME] = list(outcomes)
    return chosen or None

