"""``WindowDataset``: map-style windows over the memory-mapped Arrow table of a steps split.

Nothing is materialised: the index holds one row number per window, and ``__getitem__``
slices the memory-mapped table (zero-copy) and decodes only the wanted columns. A worker
process gets the ``datasets.Dataset`` (which pickles as its cache-file paths) and the index,
never the table, and reopens the memory map on first use.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import pyarrow as pa
import torch
from torch.utils.data import Dataset, DistributedSampler

from orbitdata import schema as S
from orbitdata.load.collate import WindowBatch
from orbitdata.load.config import IS_PAD, WindowConfig
from orbitdata.load.decode import WindowDecoder, configure_process
from orbitdata.load.index import Episodes, WindowIndex, build_index, check_windows, find_episodes


def _key_column(table: pa.Table, name: str) -> np.ndarray:
    return table.column(name).to_numpy()  # (rows,) int32


def distributed_rank() -> tuple[int, int]:
    """(rank, world_size) of this process: from ``torch.distributed`` when it is initialised."""
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


class WindowDataset(Dataset):
    """Windows of ``context + horizon`` frames from a steps split, never crossing an episode.

    Args:
        steps: the steps split as returned by ``datasets.load_dataset(path, split=...)``
            (memory-mapped; no ``.filter``/``.select`` index mapping: select episodes with
            ``episodes`` instead).
        config: window length, stride, padding, columns and image size.
        episodes: ``episode_index`` values to cut windows from; ``None`` = all.
        where: how errors name the data, e.g. "split 'train' of ./orbit_planner".

    An item is a dict of tensors over T frames, keyed by column name (see ``orbitdata.load``),
    plus ``is_pad`` (T,) bool. Order is the table order; shuffle with :meth:`sampler`. Batch
    with ``DataLoader(ds, batch_size, sampler=ds.sampler(seed=...), collate_fn=collate_windows)``:
    each batch is then decoded in place, with no stacking copy.
    """

    def __init__(
        self,
        steps,
        config: WindowConfig = WindowConfig(),
        episodes: Sequence[int] | None = None,
        where: str = "the steps table",
    ):
        if getattr(steps, "_indices", None) is not None:
            raise ValueError(
                f"{where} has an index mapping (from .filter/.select/.shuffle); select episodes with "
                "episodes=... instead, or call steps.flatten_indices() first"
            )
        self.steps = steps
        self.config = config
        self.where = where
        table = steps.data.table
        self.columns = config.wanted(table.column_names)
        self.found: Episodes = find_episodes(
            _key_column(table, S.EPISODE_INDEX), _key_column(table, S.FRAME_INDEX), where
        )
        keep = None if episodes is None else np.asarray(episodes, dtype=np.int64)
        self.index: WindowIndex = build_index(self.found, config, keep)
        check_windows(
            self.found.lengths if keep is None else self.found.lengths[np.isin(self.found.ids, keep)], config, where
        )
        self.episodes = np.unique(self.index.episode)  # (E,) episodes that give at least one window
        self._pid: int | None = None
        self._table: pa.Table | None = None
        self._decoder: WindowDecoder | None = None

    def __getstate__(self):
        state = dict(self.__dict__)
        state.update(_pid=None, _table=None, _decoder=None)  # the memory map is reopened in the worker
        return state

    def _open(self) -> None:
        configure_process()
        table = self.steps.data.table.select(list(self.columns))
        self._decoder = WindowDecoder(table.schema, self.columns, self.config)
        self._table, self._pid = table, os.getpid()

    def __len__(self) -> int:
        return len(self.index)

    def _rows(self, i: int) -> pa.Table:
        if self._pid != os.getpid():
            self._open()
        n = len(self.index)
        if not -n <= i < n:
            raise IndexError(f"window {i} out of range: {self.where} has {n} windows")
        return self._table.slice(int(self.index.row[i]), int(self.index.n_real[i]))

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        rows = self._rows(i)  # opens the table in a new process, so first
        return self._decoder(rows)

    def __getitems__(self, indices: Sequence[int]) -> WindowBatch | list:
        """A batch decoded in place; ``collate_windows`` returns it without a copy."""
        rows = [self._rows(int(i)) for i in indices]
        if not rows:
            return []
        stacked = self._decoder.allocate(rows[0], batch=len(rows))
        for j, r in enumerate(rows):
            self._decoder.decode_into(r, {k: v[j] for k, v in stacked.items()})
        return WindowBatch(stacked)

    def sampler(
        self,
        shuffle: bool = True,
        seed: int = 0,
        drop_last: bool = False,
        rank: int | None = None,
        world_size: int | None = None,
    ) -> DistributedSampler:
        """A sampler whose order is a pure function of (seed, epoch): call ``set_epoch(epoch)``.

        Under DDP (``torch.distributed`` initialised) each rank gets its share; elsewhere one
        process gets every window.
        """
        default_rank, default_world = distributed_rank()
        return DistributedSampler(
            self,
            num_replicas=default_world if world_size is None else world_size,
            rank=default_rank if rank is None else rank,
            shuffle=shuffle,
            seed=seed,
            drop_last=drop_last,
        )

    @property
    def keys(self) -> tuple[str, ...]:
        """The keys of every item."""
        return (*self.columns, IS_PAD)

    def __repr__(self) -> str:
        c = self.config
        return (
            f"WindowDataset({len(self)} windows of {c.context}+{c.horizon} frames from "
            f"{len(self.episodes)} episodes of {self.where}, stride={c.stride}, pad={c.pad})"
        )
