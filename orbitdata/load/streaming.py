"""``StreamingWindowDataset``: windows from ``load_dataset(..., streaming=True)``, one episode at a time.

The stream is read as Arrow record batches; the rows of one episode are buffered until the
next episode starts, then cut into windows with the same index and decoder as the map-style
dataset, so both yield the same windows.

Work is split over ``world_size`` ranks x ``num_workers`` DataLoader workers ("units"):

* by shard (``datasets.distributed.split_dataset_by_node``, strategy "shards") when the split
  has at least as many Parquet shards as units: each unit reads only its files. An episode
  never spans two shards, so windows stay whole.
* otherwise by episode: every unit reads the stream and keeps every ``units``-th episode
  (cheap: unwanted rows are skipped without decoding). Frame-level splitting, what
  ``split_dataset_by_node`` would fall back to, would cut episodes apart, so it is never used.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import numpy as np
import pyarrow as pa
import torch
from torch.utils.data import IterableDataset, get_worker_info

from orbitdata import schema as S
from orbitdata.load.config import WindowConfig
from orbitdata.load.decode import WindowDecoder, configure_process
from orbitdata.load.index import find_episodes, window_starts
from orbitdata.load.windows import distributed_rank


class StreamingWindowDataset(IterableDataset):
    """Windows streamed from an ``IterableDataset`` of steps, split across ranks and workers.

    Args:
        steps: ``load_dataset(path, split=..., streaming=True)`` (any format; read as Arrow).
        config: window length, stride, padding, columns and image size.
        episodes: ``episode_index`` values to keep; ``None`` = all.
        lengths: ``{episode_index: length}`` from the episodes table, checked against the
            rows streamed (optional).
        shuffle_buffer: episodes held at once to shuffle windows across; 0 = stream order.
            Memory is about this many episodes of encoded rows.
        seed: with the epoch (:meth:`set_epoch`), fixes the shuffle.
        rank, world_size: this process's DDP rank; default from ``torch.distributed``.
        batch_rows: rows per Arrow batch read from the stream.
        where: how errors name the data.

    With ``persistent_workers=True`` a DataLoader keeps its copy of the dataset, so
    ``set_epoch`` must be called before the workers start.
    """

    def __init__(
        self,
        steps,
        config: WindowConfig = WindowConfig(),
        episodes: Sequence[int] | None = None,
        lengths: Mapping[int, int] | None = None,
        shuffle_buffer: int = 0,
        seed: int = 0,
        rank: int | None = None,
        world_size: int | None = None,
        batch_rows: int = 256,
        where: str = "the steps stream",
    ):
        if shuffle_buffer < 0:
            raise ValueError(f"shuffle_buffer={shuffle_buffer}: give a number of episodes >= 0 (0 = no shuffle)")
        if steps.column_names is not None:
            config.wanted(steps.column_names)  # raises early for a missing column
        self.steps = steps.with_format("arrow")
        self.config = config
        self.episodes = None if episodes is None else frozenset(int(e) for e in episodes)
        self.lengths = None if lengths is None else {int(k): int(v) for k, v in lengths.items()}
        self.shuffle_buffer, self.seed, self.epoch = shuffle_buffer, seed, 0
        self.rank, self.world_size, self.batch_rows, self.where = rank, world_size, batch_rows, where

    def set_epoch(self, epoch: int) -> None:
        """Reshuffle for this epoch (the order is a pure function of seed, epoch and the units)."""
        self.epoch = int(epoch)

    def _units(self) -> tuple[int, int]:
        worker = get_worker_info()
        wid, workers = (worker.id, worker.num_workers) if worker is not None else (0, 1)
        default_rank, default_world = distributed_rank()
        rank = default_rank if self.rank is None else self.rank
        world = default_world if self.world_size is None else self.world_size
        if not 0 <= rank < world:
            raise ValueError(f"rank={rank} is outside world_size={world}")
        return rank * workers + wid, world * workers

    def _episode_tables(self, steps, keep) -> Iterator[tuple[int, pa.Table]]:
        """(episode_index, rows) for every episode ``keep(e)`` accepts, in stream order."""
        current, wanted, parts, seen = None, False, [], set()
        for batch in steps.iter(batch_size=self.batch_rows):
            ep = batch.column(S.EPISODE_INDEX).to_numpy()  # (B,) int32
            bounds = [0, *(np.flatnonzero(ep[1:] != ep[:-1]) + 1).tolist(), len(ep)]
            for a, b in zip(bounds[:-1], bounds[1:]):
                e = int(ep[a])
                if e != current:
                    if wanted:
                        yield current, pa.concat_tables(parts)
                    if e in seen:
                        raise ValueError(
                            f"episode {e} appears twice in {self.where}: its rows are not contiguous; "
                            "run `orbitdata validate`"
                        )
                    seen.add(e)
                    current, wanted, parts = e, keep(e), []
                if wanted:
                    parts.append(batch.slice(a, b - a))
        if wanted:
            yield current, pa.concat_tables(parts)

    def _check(self, episode: int, rows: pa.Table) -> None:
        find_episodes(rows.column(S.EPISODE_INDEX).to_numpy(), rows.column(S.FRAME_INDEX).to_numpy(), self.where)
        if self.lengths is not None and self.lengths.get(episode, rows.num_rows) != rows.num_rows:
            raise ValueError(
                f"episode {episode}: the episodes table says {self.lengths[episode]} frames but {self.where} "
                f"streams {rows.num_rows}; run `orbitdata validate`"
            )

    def _share(self, unit: int, units: int):
        """This unit's stream, and the predicate that keeps this unit's selected episodes."""
        steps = self.steps
        if steps.column_names is not None:
            steps = steps.select_columns(list(self.config.wanted(steps.column_names)))
        by_shard = units == 1 or steps.num_shards >= units
        if by_shard and units > 1:
            import fsspec.asyn
            from datasets.distributed import split_dataset_by_node

            fsspec.asyn.reset_lock()  # a lock inherited through fork would hang remote reads
            steps = split_dataset_by_node(steps, rank=unit, world_size=units, strategy="shards")
        ordinal = -1  # selected episodes seen so far: the same count in every unit

        def keep(e: int) -> bool:
            nonlocal ordinal
            if self.episodes is not None and e not in self.episodes:
                return False
            ordinal += 1
            return by_shard or ordinal % units == unit

        return steps, keep

    def _window(self, rows: pa.Table, start: int) -> pa.Table:
        return rows.slice(start, min(self.config.length, rows.num_rows - start))

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        configure_process()
        unit, units = self._units()
        steps, keep = self._share(unit, units)
        rng = np.random.default_rng([self.seed, self.epoch, unit, units])
        decoder = None
        held: dict[int, list] = {}  # episode -> [rows, windows not yet yielded]
        pending: list[tuple[int, int]] = []  # (episode, start frame) of the held windows

        def pop() -> dict[str, torch.Tensor]:
            j = int(rng.integers(len(pending)))
            pending[j], pending[-1] = pending[-1], pending[j]
            episode, start = pending.pop()
            rows = held[episode][0]
            held[episode][1] -= 1
            if held[episode][1] == 0:
                del held[episode]
            return decoder(self._window(rows, start))

        for episode, rows in self._episode_tables(steps, keep):
            self._check(episode, rows)
            if decoder is None:
                decoder = WindowDecoder(rows.schema, self.config.wanted(rows.column_names), self.config)
            _, starts = window_starts(np.array([rows.num_rows]), self.config)
            if not self.shuffle_buffer:
                for start in starts.tolist():
                    yield decoder(self._window(rows, start))
                continue
            if len(starts):
                held[episode] = [rows, len(starts)]
                pending.extend((episode, start) for start in starts.tolist())
            while len(held) >= self.shuffle_buffer:
                yield pop()
        while pending:
            yield pop()

    def __repr__(self) -> str:
        c = self.config
        return (
            f"StreamingWindowDataset({c.context}+{c.horizon} frames, stride={c.stride}, pad={c.pad}, "
            f"shuffle_buffer={self.shuffle_buffer}, from {self.where})"
        )
