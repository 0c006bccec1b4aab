"""The steps and episodes tables of one split, read through ``datasets.load_dataset``."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa

from orbitdata import schema as S
from orbitdata.load.source import local_folder

EPISODES_CONFIG = "episodes"  # the card's config name for the episodes table


def load_steps(source: str | Path, split: str, streaming: bool, load_kwargs: dict, columns=None):
    """The steps table of one split: a memory-mapped ``Dataset``, or an ``IterableDataset`` in Arrow format."""
    from datasets import load_dataset

    kwargs = dict(load_kwargs)
    if local_folder(source) is not None and "data_files" not in kwargs and "data_dir" not in kwargs:
        # Named explicitly, the files' mtimes enter the cache key; through the card's configs
        # they do not, and a rewritten dataset would be read from a stale Arrow cache.
        kwargs["data_files"] = {split: f"{S.DATA_DIR}/{split}-*.parquet"}
    if streaming and columns is not None:
        kwargs["columns"] = list(columns)  # Parquet reads only these columns
    steps = load_dataset(str(source), split=split, streaming=streaming, **kwargs)
    return steps.with_format("arrow") if streaming else steps


def load_episode_table(source: str | Path, split: str, load_kwargs: dict) -> pa.Table:
    """The episodes config of one split as an Arrow table (small: one row per episode)."""
    from datasets import load_dataset

    kwargs = {k: v for k, v in load_kwargs.items() if k not in ("columns", "streaming", "name")}
    episodes = load_dataset(str(source), EPISODES_CONFIG, split=split, streaming=True, **kwargs)
    batches = list(episodes.with_format("arrow").iter(batch_size=100_000))
    if not batches:
        raise ValueError(f"{source}: split {split!r} has no episodes")
    return pa.concat_tables(batches)
