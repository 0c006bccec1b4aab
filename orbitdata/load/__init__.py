"""Windowed PyTorch datasets over an orbitdata dataset (local folder or Hub repo).

An item is a dict of tensors over T = context + horizon consecutive frames of one episode,
keyed by the dataset's column names::

    observation.image      (T, 3, H, W) uint8 RGB
    observation.depth      (T, H, W)    float32 metres, 0 = no return
    observation.depth_low  (T, 16, 16)  float32 metres
    observation.state      (T, 16)      float32
    action                 (T, 8)       float32 (zeros on an episode's last frame)
    collision, success, is_last  (T,)   bool
    timestamp, min_clearance     (T,)   float32
    episode_index, frame_index   (T,)   int64
    is_pad                 (T,)         bool, True on frames that repeat the last real frame

Batch with ``DataLoader(..., collate_fn=collate_windows)``: a map-style batch is then decoded
in place rather than stacked (``default_collate`` works too, one copy slower).

Pipeline: ``source`` (folder or Hub repo, meta/info.json and its schema version) -> ``tables``
(load the split) -> ``select`` (episodes filter) -> ``index`` (window starts) -> ``decode``
(Arrow rows to tensors) -> ``windows`` (map-style) or ``streaming`` (iterable) -> ``collate``.

The same reader layer opens a dataset for everything else: :func:`read_meta` (info and the
normalisation stats), ``episodes`` (one episode, its rows read by row group: ``rows``) and
``summary`` (what ``orbitdata info`` shows). Only ``load_windows`` and the window datasets need
torch and ``datasets``; they import on first use.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from orbitdata.info import Info
from orbitdata.lazy import lazy_getattr
from orbitdata.load.config import IS_PAD, WindowConfig
from orbitdata.load.source import HubUnavailable, dataset_folder, is_repo_id, read_info, read_meta

if TYPE_CHECKING:
    from orbitdata.load.select import EpisodeFilter
    from orbitdata.load.streaming import StreamingWindowDataset
    from orbitdata.load.windows import WindowDataset

_LAZY = {  # name -> the module that defines it
    **dict.fromkeys(("WindowDataset",), "orbitdata.load.windows"),
    **dict.fromkeys(("StreamingWindowDataset",), "orbitdata.load.streaming"),
    **dict.fromkeys(("collate_windows",), "orbitdata.load.collate"),
    **dict.fromkeys(("EpisodeFilter",), "orbitdata.load.select"),
    **dict.fromkeys(("Episode", "load_episode", "read_episodes"), "orbitdata.load.episodes"),
}

__getattr__ = lazy_getattr(__name__, _LAZY)
__all__ = [
    "load_windows",
    "read_meta",
    "read_info",
    "Info",
    "HubUnavailable",
    "dataset_folder",
    "is_repo_id",
    "WindowConfig",
    "IS_PAD",
    *_LAZY,
]


def load_windows(
    source: str | Path,
    split: str = "train",
    context: int = WindowConfig.context,
    horizon: int = WindowConfig.horizon,
    stride: int = WindowConfig.stride,
    pad: bool = WindowConfig.pad,
    image_size: int | None = WindowConfig.image_size,
    columns: list[str] | tuple[str, ...] | None = None,
    episodes: EpisodeFilter = None,
    context_only: list[str] | tuple[str, ...] = (),
    streaming: bool = False,
    shuffle_buffer: int = 0,
    seed: int = 0,
    **load_dataset_kwargs,
) -> WindowDataset | StreamingWindowDataset:
    """Windows of ``context + horizon`` frames from one split, never crossing an episode.

    Args:
        source: a local dataset folder or a Hub repo id; read with ``datasets.load_dataset``.
        split: "train" or "test".
        context, horizon, stride, pad, image_size, columns, context_only: see :class:`WindowConfig`
            (``columns=None`` loads every step column but the privileged ``privileged.*``; name
            fewer to skip e.g. full-res depth;
            ``context_only=["observation.image"]`` decodes images of the context frames only).
        episodes: which episodes to cut windows from, through the episodes table: ``None``
            (all), a dict of column values (``{"level": "expert", "outcome": ["success"]}``),
            a predicate over the episode row (``lambda ep: ep["outcome"] != "collision"``) or
            a list of ``episode_index`` values.
        streaming: ``False``: a map-style :class:`WindowDataset` over the memory-mapped Arrow
            cache (shuffle with ``ds.sampler(seed=...)``). ``True``: a
            :class:`StreamingWindowDataset` reading the Parquet shards as it goes.
        shuffle_buffer, seed: streaming only: shuffle windows across this many episodes,
            reproducibly from (seed, epoch).
        **load_dataset_kwargs: passed to ``datasets.load_dataset`` (``cache_dir``,
            ``revision``, ``token``, ...).

    Raises:
        FileNotFoundError: no such folder, or no ``meta/info.json`` in it.
        ValueError: unknown schema version, missing column, an episodes filter that selects
            nothing, a window longer than every selected episode, inconsistent tables.
    """
    import numpy as np

    from orbitdata import schema as S
    from orbitdata.load.index import check_lengths, check_windows
    from orbitdata.load.select import select_episodes
    from orbitdata.load.streaming import StreamingWindowDataset
    from orbitdata.load.tables import load_episode_table, load_steps
    from orbitdata.load.windows import WindowDataset

    if not streaming and (shuffle_buffer or seed):
        raise ValueError(
            "shuffle_buffer/seed are for streaming=True; shuffle a map-style dataset with ds.sampler(seed=...)"
        )
    config = WindowConfig(
        context=context,
        horizon=horizon,
        stride=stride,
        pad=pad,
        image_size=image_size,
        columns=columns,
        context_only=context_only,
    )
    try:  # checks the schema version before anything is read
        read_info(source, load_dataset_kwargs.get("revision"), load_dataset_kwargs.get("token"))
    except HubUnavailable:
        pass  # offline, private or gated: load_dataset says more (or reads its own cache)
    where = f"split {split!r} of {source}"
    table = load_episode_table(source, split, load_dataset_kwargs)
    selected = select_episodes(table, episodes, split)  # (E,) sorted episode_index
    chosen = np.isin(table.column(S.EPISODE_INDEX).to_numpy(), selected)
    ids = table.column(S.EPISODE_INDEX).to_numpy()[chosen].astype(np.int64)
    lengths = table.column(S.LENGTH).to_numpy()[chosen].astype(np.int64)
    check_windows(lengths, config, where)
    keep = None if episodes is None else selected
    if not streaming:
        steps = load_steps(source, split, False, load_dataset_kwargs)
        dataset = WindowDataset(steps, config, episodes=keep, where=where)
        check_lengths(dataset.found, ids, lengths, where)
        return dataset
    steps = load_steps(source, split, True, load_dataset_kwargs)
    wanted = config.wanted(steps.column_names)  # raises for a missing column before any read
    if config.columns is not None or len(wanted) < len(steps.column_names):
        steps = load_steps(source, split, True, load_dataset_kwargs, columns=wanted)
    return StreamingWindowDataset(
        steps,
        config,
        episodes=None if keep is None else keep.tolist(),
        lengths=dict(zip(ids.tolist(), lengths.tolist())),
        shuffle_buffer=shuffle_buffer,
        seed=seed,
        where=where,
    )
