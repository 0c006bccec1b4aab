"""Compact part files (or re-shard a dataset) into the Hugging Face layout.

Output per split, in episode order: ``data/{split}-XXXXX-of-YYYYY.parquet`` (frames) and
``episodes/{split}-00000-of-00001.parquet``. A data shard closes at the first episode
boundary past ``max_shard_bytes``, so an episode never spans two files. Row groups hold
``row_group_rows`` rows whatever the episode lengths. The bytes depend only on the source
rows and the config, never on how the source was produced.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from orbitdata import schema as S
from orbitdata.config import DatasetConfig
from orbitdata.load.rows import RowReader, readable
from orbitdata.scenario.config import STATIC
from orbitdata.write.parts import atomic_write, episodes_part, parts_dir, remove_temporaries, steps_part
from orbitdata.write.stats import StatsAccumulator


def _image_bytes(table: pa.Table) -> int:
    """Estimated stored size of ``table``: its encoded images plus ~1.2 KB a row for the rest."""
    total = 0
    for name in S.IMAGE_COLUMNS:
        # Count the bytes of these rows only (a slice shares its parent's buffers).
        total += pc.sum(pc.binary_length(pc.struct_field(table.column(name), "bytes"))).as_py() or 0
    # Everything else is ~1.2 KB/row before compression (depth_low dominates).
    return total + 1200 * table.num_rows


class _ShardWriter:
    """Writes one split's frames to numbered shards under temporary names."""

    def __init__(self, out: Path, split: str, storage: DatasetConfig, tier: str = STATIC):
        self.out, self.split, self.storage = out, split, storage
        self.schema = S.with_hf_metadata(S.step_schema(tier), "data", tier)
        self.files: list[Path] = []
        self.writer: pq.ParquetWriter | None = None
        self.buffer: list[pa.Table] = []
        self.buffered = 0
        self.shard_bytes = 0
        self.shard_rows = 0

    def _open(self) -> None:
        path = self.out / S.DATA_DIR / f".tmp-{self.split}-{len(self.files):05d}.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        self.files.append(path)
        # No dictionary encoding: images are unique blobs, and a dictionary's fallback point
        # would depend on how the input happens to be chunked, breaking byte-identity.
        self.writer = pq.ParquetWriter(path, self.schema, compression=self.storage.compression, use_dictionary=False)
        self.shard_bytes = self.shard_rows = 0

    def _flush(self, final: bool) -> None:
        rows = self.storage.row_group_rows
        while self.buffered >= rows or (final and self.buffered):
            table = pa.concat_tables(self.buffer)
            take = min(rows, table.num_rows)
            # One chunk per column, so the bytes never depend on the source's chunking.
            group = table.slice(0, take).cast(self.schema).combine_chunks()
            self.writer.write_table(group, row_group_size=rows)
            rest = table.slice(take)
            self.buffer, self.buffered = ([rest] if rest.num_rows else []), rest.num_rows

    def add_episode(self, table: pa.Table) -> tuple[int, int, int]:
        """Append one episode's rows; returns (shard number, first row, end row)."""
        if self.writer is None or self.shard_bytes >= self.storage.max_shard_bytes:
            self._close_current()
            self._open()
        start = self.shard_rows
        self.buffer.append(table)
        self.buffered += table.num_rows
        self.shard_rows += table.num_rows
        self.shard_bytes += _image_bytes(table)
        self._flush(final=False)
        return len(self.files) - 1, start, self.shard_rows

    def _close_current(self) -> None:
        if self.writer is not None:
            self._flush(final=True)
            self.writer.close()
            with open(self.files[-1], "rb+") as f:
                os.fsync(f.fileno())
            self.writer = None

    def finish(self) -> list[str]:
        """Close and rename to final names; returns the relative paths."""
        self._close_current()
        n = len(self.files)
        names = []
        for i, tmp in enumerate(self.files):
            rel = S.shard_path(S.DATA_DIR, self.split, i, n)
            os.replace(tmp, self.out / rel)
            names.append(rel)
        return names


def _source_from_parts(out: Path, split: str) -> Iterator[tuple[dict, pa.Table]]:
    """(episode row, frames) for every episode of ``split`` in the parts, in episode order."""
    units = sorted(p.name[: -len(".episodes.parquet")] for p in parts_dir(out).glob("unit-*.episodes.parquet"))
    for name in units:
        episodes = readable(lambda: pq.read_table(episodes_part(out, name)), episodes_part(out, name)).to_pylist()
        if not any(row[S.SPLIT] == split for row in episodes):
            continue
        steps = readable(lambda: pq.read_table(steps_part(out, name)), steps_part(out, name))
        offset = 0
        for row in episodes:
            if row[S.SPLIT] == split:
                yield row, steps.slice(offset, row[S.LENGTH])
            offset += row[S.LENGTH]


def _source_from_shards(out: Path, split: str) -> Iterator[tuple[dict, pa.Table]]:
    """(episode row, frames) of ``split`` from an existing layout, with a few row groups in memory."""
    files = sorted((out / S.EPISODES_DIR).glob("*.parquet"))
    if not files:
        raise FileNotFoundError(f"{out} has neither parts/ nor episodes/*.parquet to shard")
    episodes = pa.concat_tables([readable(lambda f=f: pq.read_table(f), f) for f in files])
    episodes = episodes.filter(pc.equal(episodes.column(S.SPLIT), split))
    episodes = episodes.take(pc.sort_indices(episodes, [(S.EPISODE_INDEX, "ascending")]))
    reader, current = None, None
    for row in episodes.to_pylist():
        if row[S.DATA_FILE] != current:
            current = row[S.DATA_FILE]
            reader = RowReader(out / current, memory_map=True)
        frames = reader.rows(row[S.ROW_START], row[S.ROW_END])
        held = frames.column(S.EPISODE_INDEX)
        if len(held) == 0 or held[0].as_py() != row[S.EPISODE_INDEX] or held[-1].as_py() != row[S.EPISODE_INDEX]:
            raise ValueError(
                f"{out}: {S.EPISODES_DIR}/ says episode {row[S.EPISODE_INDEX]} is rows {row[S.ROW_START]}-"
                f"{row[S.ROW_END]} of {current}, which hold other frames (a re-shard cut between its data and "
                "episodes shards?); restore the dataset (download or generate it again) before re-sharding"
            )
        yield row, frames


def _check_listed(out: Path) -> None:
    """Re-sharding existing shards reads the episodes tables and replaces every data shard: rows
    they do not list would be lost with the old shards. So each data file the tables name must hold
    exactly the rows listed in it, and a split with data shards must be listed. Shards of another
    layout that no table names (a re-shard cut before it removed the old ones) are leftovers."""
    per_file: dict[str, int] = {}
    for table in sorted((out / S.EPISODES_DIR).glob("*.parquet")):
        t = readable(lambda: pq.read_table(table, columns=[S.DATA_FILE, S.LENGTH]), table)
        for rel, length in zip(t.column(S.DATA_FILE).to_pylist(), t.column(S.LENGTH).to_pylist()):
            per_file[rel] = per_file.get(rel, 0) + length
    for rel, rows in sorted(per_file.items()):
        held = (
            readable(lambda: pq.ParquetFile(out / rel).metadata.num_rows, out / rel) if (out / rel).is_file() else None
        )
        if held != rows:
            has = "is missing" if held is None else f"holds {held} frames"
            raise ValueError(
                f"{out}: {S.EPISODES_DIR}/ lists {rows} frames in {rel}, which {has}; restore the dataset "
                "(download or generate it again) before re-sharding"
            )
    for split in S.SPLITS:
        shards = [
            p for p in (out / S.DATA_DIR).glob(f"{split}-*.parquet") if S.SHARD_RE.match(f"{S.DATA_DIR}/{p.name}")
        ]
        if shards and not any(rel.startswith(f"{S.DATA_DIR}/{split}-") for rel in per_file):
            raise ValueError(
                f"{out}: {len(shards)} {split} data shard(s) and no episode of them in {S.EPISODES_DIR}/; restore "
                f"{S.EPISODES_DIR}/{split}-*.parquet (download or generate the dataset again) before re-sharding"
            )


def _rows_per_split(out: Path, from_parts: bool) -> dict[str, int]:
    paths = (
        list(parts_dir(out).glob("unit-*.episodes.parquet"))
        if from_parts
        else list((out / S.EPISODES_DIR).glob("*.parquet"))
    )
    totals = {s: 0 for s in S.SPLITS}
    for p in paths:
        t = readable(lambda: pq.read_table(p, columns=[S.SPLIT, S.LENGTH]), p)
        for split, length in zip(t.column(S.SPLIT).to_pylist(), t.column(S.LENGTH).to_pylist()):
            totals[split] += length
    return totals


@dataclass
class ShardResult:
    files: list[str]  # relative paths of data and episodes shards
    episodes: pa.Table  # the final episodes table (both splits)
    stats: dict  # train-split stats


def write_shards(out: Path, storage: DatasetConfig, tier: str = STATIC) -> ShardResult:
    """Write final data/episodes shards from parts/ (if present) or from existing shards.

    ``storage``: the compression, rows per row group and shard size limit of the config;
    ``tier``: the scenario tier, whose columns the tables have.
    """
    from_parts = parts_dir(out).is_dir() and any(parts_dir(out).glob("unit-*.episodes.parquet"))
    for folder in (out / S.DATA_DIR, out / S.EPISODES_DIR):
        remove_temporaries(folder)
    totals = _rows_per_split(out, from_parts)
    if not from_parts:
        _check_listed(out)
    stats = StatsAccumulator(totals["train"])
    files, all_rows = [], []
    for split in S.SPLITS:
        if totals[split] == 0:
            continue
        writer = _ShardWriter(out, split, storage, tier)
        rows = []
        source = _source_from_parts(out, split) if from_parts else _source_from_shards(out, split)
        for row, frames in source:
            shard, start, end = writer.add_episode(frames)
            if split == "train":
                stats.update(frames)
            rows.append(dict(row, **{S.DATA_FILE: shard, S.ROW_START: start, S.ROW_END: end}))
        data_files = writer.finish()
        for r in rows:
            r[S.DATA_FILE] = data_files[r[S.DATA_FILE]]
        table = pa.Table.from_pylist(rows, schema=S.with_hf_metadata(S.episode_schema(tier), "episodes", tier))
        rel = S.shard_path(S.EPISODES_DIR, split, 0, 1)
        sink = pa.BufferOutputStream()
        pq.write_table(table, sink, compression=storage.compression)
        atomic_write(out / rel, sink.getvalue().to_pybytes())
        files += data_files + [rel]
        all_rows += rows
    # Shards from an earlier layout (other counts) would shadow the new ones in globs.
    keep = set(files)
    for folder in (S.DATA_DIR, S.EPISODES_DIR):
        for path in (out / folder).glob("*.parquet"):
            if f"{folder}/{path.name}" not in keep:
                path.unlink()
    episodes = pa.Table.from_pylist(all_rows, schema=S.episode_schema(tier))
    return ShardResult(files=files, episodes=episodes, stats=stats.result())
