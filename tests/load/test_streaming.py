"""Streaming windows: the same windows as map-style, split whole across ranks and DataLoader workers."""

from __future__ import annotations

import shutil
from collections import Counter

import pytest
import torch
from torch.utils.data import DataLoader

from orbitdata import schema as S
from orbitdata.config import DatasetConfig
from orbitdata.load import IS_PAD, StreamingWindowDataset, load_windows
from orbitdata.write.shard import write_shards

LIGHT = [S.IMAGE, S.STATE, S.ACTION, S.SUCCESS]  # no full-res depth: faster, same code paths


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("hf-cache"))


@pytest.fixture(scope="module")
def sharded(tiny_dataset_master, tmp_path_factory):
    """The tiny dataset re-sharded to one episode per Parquet file (several shards per split)."""
    out = tmp_path_factory.mktemp("sharded") / "orbit"
    shutil.copytree(tiny_dataset_master, out)
    write_shards(out, DatasetConfig(max_shard_bytes=1, row_group_rows=64))
    assert len(list((out / S.DATA_DIR).glob("train-*.parquet"))) >= 4
    return out


def key(item: dict) -> tuple[int, int]:
    """(episode, first frame) of a window, or of every window of a batch."""
    return int(item[S.EPISODE_INDEX][0]), int(item[S.FRAME_INDEX][0])


def batch_keys(batch: dict) -> list[tuple[int, int]]:
    return [(int(e), int(f)) for e, f in zip(batch[S.EPISODE_INDEX][:, 0], batch[S.FRAME_INDEX][:, 0])]


@pytest.fixture(scope="module")
def map_style(tiny_dataset_master, cache) -> dict:
    ds = load_windows(tiny_dataset_master, columns=LIGHT, cache_dir=cache)
    return {key(ds[i]): ds[i] for i in range(len(ds))}


def test_streaming_yields_exactly_the_map_style_windows(tiny_dataset_master, cache, map_style):
    stream = load_windows(tiny_dataset_master, columns=LIGHT, streaming=True, cache_dir=cache)
    assert isinstance(stream, StreamingWindowDataset)
    seen = Counter()
    for item in stream:
        k = key(item)
        seen[k] += 1
        assert set(item) == set(map_style[k])
        for name, value in item.items():
            assert torch.equal(value, map_style[k][name]), (k, name)
    assert seen == Counter(map_style.keys())


def test_streaming_with_filter_and_padding_matches_map_style(tiny_dataset_master, cache):
    kwargs = dict(
        columns=[S.ACTION, S.IMAGE],
        context_only=[S.IMAGE],
        pad=True,
        context=4,
        horizon=30,
        cache_dir=cache,
        episodes=lambda ep: ep[S.LEVEL] != "expert",
    )
    mapped = load_windows(tiny_dataset_master, **kwargs)
    streamed = list(load_windows(tiny_dataset_master, streaming=True, **kwargs))
    assert sorted(map(key, streamed)) == sorted(key(mapped[i]) for i in range(len(mapped)))
    assert any(item[IS_PAD].any() for item in streamed)
    assert all(item[S.IMAGE].shape[0] == 4 for item in streamed)
    by_key = {key(mapped[i]): mapped[i] for i in range(len(mapped))}
    for item in streamed:
        assert all(torch.equal(v, by_key[key(item)][k]) for k, v in item.items())


def test_shuffle_is_a_pure_function_of_seed_and_epoch(tiny_dataset_master, cache):
    def order(seed: int, epoch: int) -> list:
        stream = load_windows(
            tiny_dataset_master, columns=[S.ACTION], streaming=True, shuffle_buffer=3, seed=seed, cache_dir=cache
        )
        stream.set_epoch(epoch)
        return [key(item) for item in stream]

    plain = load_windows(tiny_dataset_master, columns=[S.ACTION], streaming=True, cache_dir=cache)
    plain = [key(item) for item in plain]
    first = order(seed=1, epoch=0)
    assert sorted(first) == sorted(plain) and first != plain
    assert order(seed=1, epoch=0) == first
    assert order(seed=1, epoch=1) != first
    assert order(seed=2, epoch=0) != first


@pytest.mark.parametrize("layout", ["one shard", "sharded"])
def test_ranks_get_disjoint_whole_episodes(layout, tiny_dataset_master, sharded, cache):
    source = tiny_dataset_master if layout == "one shard" else sharded
    stream = load_windows(source, columns=[S.ACTION], streaming=True, cache_dir=cache)
    assert stream.steps.num_shards == (1 if layout == "one shard" else 4)  # by episode / by shard
    everything = sorted(key(item) for item in stream)
    parts = []
    for rank in (0, 1):
        stream.rank, stream.world_size = rank, 2
        parts.append([key(item) for item in stream])
    assert sorted(parts[0] + parts[1]) == everything
    episodes = [{e for e, _ in part} for part in parts]
    assert episodes[0] and episodes[1] and not episodes[0] & episodes[1]  # split by whole episodes


@pytest.mark.parametrize("layout", ["one shard", "sharded"])
def test_dataloader_with_two_workers_streams_every_window_once(layout, tiny_dataset_master, sharded, cache):
    source = tiny_dataset_master if layout == "one shard" else sharded
    stream = load_windows(source, columns=[S.ACTION, S.STATE], streaming=True, cache_dir=cache)
    loader = DataLoader(stream, batch_size=16, num_workers=2, timeout=60)
    got = [k for batch in loader for k in batch_keys(batch)]
    assert Counter(got) == Counter(key(item) for item in stream)
