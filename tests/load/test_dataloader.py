"""Map-style training use: DataLoader workers, order as a pure function of (seed, epoch), DDP shares, pickling."""

from __future__ import annotations

import pickle

import pytest
import torch
from torch.utils.data import DataLoader

from orbitdata import schema as S
from orbitdata.load import IS_PAD, WindowDataset, collate_windows, load_windows

COLUMNS = [S.IMAGE, S.DEPTH_LOW, S.STATE, S.ACTION, S.COLLISION, S.SUCCESS]


@pytest.fixture(scope="module")
def windows(tiny_dataset_master, tmp_path_factory) -> WindowDataset:
    return load_windows(tiny_dataset_master, columns=COLUMNS, cache_dir=str(tmp_path_factory.mktemp("hf-cache")))


def run(ds: WindowDataset, seed: int, epoch: int, workers: int, collate=collate_windows, batches: int = 4) -> list:
    sampler = ds.sampler(seed=seed)
    sampler.set_epoch(epoch)
    loader = DataLoader(
        ds, batch_size=8, sampler=sampler, num_workers=workers, collate_fn=collate, timeout=60 if workers else 0
    )
    out = []
    for i, batch in enumerate(loader):
        if i == batches:
            break
        out.append(batch)
    return out


def same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(
        x.keys() == y.keys() and all(torch.equal(x[k], y[k]) for k in x) for x, y in zip(a, b)
    )


def test_two_workers_are_deterministic_for_a_seed_and_match_no_workers(windows):
    first = run(windows, seed=7, epoch=0, workers=2)
    assert same(first, run(windows, seed=7, epoch=0, workers=2))
    assert same(first, run(windows, seed=7, epoch=0, workers=0))
    assert same(first, run(windows, seed=7, epoch=0, workers=2, collate=None))  # default_collate too
    batch = first[0]
    assert batch[S.IMAGE].shape == (8, 20, 3, 64, 64) and batch[S.IMAGE].dtype == torch.uint8
    assert batch[S.DEPTH_LOW].shape == (8, 20, 16, 16) and batch[S.STATE].shape == (8, 20, 16)
    assert batch[S.ACTION].shape == (8, 20, 8) and batch[IS_PAD].shape == (8, 20)


def test_order_is_a_pure_function_of_seed_and_epoch(windows):
    def order(seed, epoch):
        sampler = windows.sampler(seed=seed)
        sampler.set_epoch(epoch)
        return list(sampler)

    assert order(0, 0) == order(0, 0) and sorted(order(0, 0)) == list(range(len(windows)))
    assert order(0, 1) != order(0, 0) and order(1, 0) != order(0, 0)
    assert list(windows.sampler(shuffle=False)) == list(range(len(windows)))


def test_ddp_ranks_share_the_windows(windows):
    shares = [list(windows.sampler(seed=3, rank=r, world_size=2, drop_last=True)) for r in (0, 1)]
    assert len(shares[0]) == len(shares[1]) == len(windows) // 2
    assert not set(shares[0]) & set(shares[1])


def test_pickling_sends_paths_not_tables(windows):
    blob = pickle.dumps(windows)
    assert len(blob) < 200_000  # the index and cache-file paths, not the frames
    copy = pickle.loads(blob)
    for i in (0, len(windows) - 1):
        a, b = windows[i], copy[i]
        assert all(torch.equal(a[k], b[k]) for k in a)
