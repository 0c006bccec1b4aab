"""Map-style windows: contents equal the stored rows for every key; episodes, stride, padding, resize."""

from __future__ import annotations

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import torch
from torch.utils.data import default_collate

from orbitdata import schema as S
from orbitdata.codecs import decode_depth, decode_rgb
from orbitdata.load import IS_PAD, WindowDataset, collate_windows, load_windows
from orbitdata.load.config import WindowConfig

EVERY_COLUMN = tuple(S.STEP_SCHEMA.names)


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("hf-cache"))


@pytest.fixture(scope="module")
def reference(tiny_dataset_master) -> dict:
    """The train rows read straight from Parquet, images decoded with the generator's codecs."""
    files = sorted((tiny_dataset_master / S.DATA_DIR).glob("train-*.parquet"))
    table = pa.concat_tables([pq.read_table(f) for f in files])
    ref = {}
    for name in EVERY_COLUMN:
        col = table.column(name)
        if name == S.IMAGE:
            ref[name] = np.stack([decode_rgb(r["bytes"]).transpose(2, 0, 1) for r in col.to_pylist()])
        elif name == S.DEPTH:
            ref[name] = np.stack([decode_depth(r["bytes"]) for r in col.to_pylist()])
        else:
            ref[name] = np.asarray(col.to_pylist())
    ref[S.DEPTH_LOW] = ref[S.DEPTH_LOW].reshape(-1, S.DEPTH_LOW_SIDE, S.DEPTH_LOW_SIDE)
    ref["row_of"] = {(e, f): i for i, (e, f) in enumerate(zip(ref[S.EPISODE_INDEX], ref[S.FRAME_INDEX]))}
    ref["lengths"] = {int(e): int(n) for e, n in zip(*np.unique(ref[S.EPISODE_INDEX], return_counts=True))}
    return ref


@pytest.fixture(scope="module")
def windows(tiny_dataset_master, cache) -> WindowDataset:
    return load_windows(tiny_dataset_master, cache_dir=cache)


def expected_rows(ref: dict, item: dict) -> np.ndarray:
    """Stored row of every frame of a window: its real frames, then the last one repeated."""
    ep = int(item[S.EPISODE_INDEX][0])
    first = int(item[S.FRAME_INDEX][0])
    n_real = int((~item[IS_PAD]).sum())
    rows = [ref["row_of"][(ep, first + k)] for k in range(n_real)]
    return np.array(rows + [rows[-1]] * (len(item[IS_PAD]) - n_real))


def assert_window_matches(ref: dict, item: dict) -> None:
    rows = expected_rows(ref, item)
    for name in EVERY_COLUMN:
        if name not in item:
            continue
        got = item[name].numpy()
        want = ref[name][rows]
        assert got.shape == want.shape, name
        np.testing.assert_array_equal(got, want.astype(got.dtype), err_msg=name)
        assert want.dtype.kind != "f" or got.dtype == np.float32


def test_every_key_equals_the_stored_rows(windows, reference):
    T = 20
    item = windows[0]
    assert set(item) == set(EVERY_COLUMN) | {IS_PAD}
    shapes = {
        S.IMAGE: (T, 3, 64, 64),
        S.DEPTH: (T, 64, 64),
        S.DEPTH_LOW: (T, 16, 16),
        S.STATE: (T, 16),
        S.ACTION: (T, 8),
        S.COLLISION: (T,),
        S.SUCCESS: (T,),
        S.EPISODE_INDEX: (T,),
        IS_PAD: (T,),
    }
    for name, shape in shapes.items():
        assert tuple(item[name].shape) == shape, name
    assert item[S.IMAGE].dtype == torch.uint8 and item[S.DEPTH_LOW].dtype == torch.float32
    assert item[S.COLLISION].dtype == torch.bool and item[IS_PAD].dtype == torch.bool
    # Every 5th window and the last: every stored row is compared, at several window positions.
    for i in [*range(0, len(windows), 5), len(windows) - 1]:
        item = windows[i]
        assert not item[IS_PAD].any()
        assert_window_matches(reference, item)


def test_windows_never_cross_an_episode_and_cover_every_start(tiny_dataset_master, cache, reference):
    ds = load_windows(tiny_dataset_master, columns=[S.SUCCESS], cache_dir=cache)
    T = ds.config.length
    starts = {}
    for i in range(len(ds)):
        item = ds[i]
        ep, frames = int(item[S.EPISODE_INDEX][0]), item[S.FRAME_INDEX].numpy()
        assert (item[S.EPISODE_INDEX].numpy() == ep).all() and ep == ds.index.episode[i]
        np.testing.assert_array_equal(frames, frames[0] + np.arange(T))
        assert frames[-1] < reference["lengths"][ep]
        starts.setdefault(ep, []).append(int(frames[0]))
    assert starts == {e: list(range(n - T + 1)) for e, n in reference["lengths"].items() if n >= T}


def test_stride_and_short_windows(tiny_dataset_master, cache, reference):
    ds = load_windows(tiny_dataset_master, context=2, horizon=3, stride=7, cache_dir=cache)
    firsts = sorted((int(ds.index.episode[i]), int(ds.index.row[i])) for i in range(len(ds)))
    expected = sum(len(range(0, n - 5 + 1, 7)) for n in reference["lengths"].values())
    assert len(ds) == len(firsts) == expected
    for i in (0, len(ds) // 2, len(ds) - 1):
        item = ds[i]
        assert item[S.FRAME_INDEX][0] % 7 == 0 and item[S.ACTION].shape == (5, 8)
        assert_window_matches(reference, item)


def test_padding_repeats_the_last_frame_and_is_pad_marks_it(tiny_dataset_master, cache, reference):
    context, horizon = 8, 12
    T = context + horizon
    ds = load_windows(tiny_dataset_master, context=context, horizon=horizon, pad=True, cache_dir=cache)
    assert len(ds) == sum(n - context + 1 for n in reference["lengths"].values())
    padded = [i for i in range(len(ds)) if ds.index.n_real[i] < T]
    assert len(padded) == len(reference["lengths"]) * horizon  # the last `horizon` starts of each episode
    for i in padded + [0, len(ds) // 2]:
        item = ds[i]
        ep, first = int(item[S.EPISODE_INDEX][0]), int(item[S.FRAME_INDEX][0])
        n_real = min(T, reference["lengths"][ep] - first)
        np.testing.assert_array_equal(item[IS_PAD].numpy(), np.arange(T) >= n_real)
        assert not item[IS_PAD][:context].any()  # the context is always real
        assert_window_matches(reference, item)  # padded frames repeat the last real one, every key


def test_columns_select_the_keys(tiny_dataset_master, cache, reference):
    ds = load_windows(tiny_dataset_master, columns=[S.IMAGE, S.ACTION], cache_dir=cache)
    item = ds[3]
    assert set(item) == {S.IMAGE, S.ACTION, S.EPISODE_INDEX, S.FRAME_INDEX, IS_PAD} == set(ds.keys)
    assert_window_matches(reference, item)


def test_context_only_columns_hold_the_context_frames_alone(tiny_dataset_master, cache, reference):
    full = load_windows(
        tiny_dataset_master, context=2, horizon=14, pad=True, columns=[S.IMAGE, S.ACTION], cache_dir=cache
    )
    cut = load_windows(
        tiny_dataset_master,
        context=2,
        horizon=14,
        pad=True,
        columns=[S.IMAGE, S.ACTION],
        context_only=[S.IMAGE],
        cache_dir=cache,
    )
    assert len(cut) == len(full)
    last = len(cut) - 1  # a padded window: the horizon runs past the episode's end
    for items in ([cut[i] for i in (0, 9, last)], [cut.__getitems__([0, 9, last]).stacked]):
        for j, item in enumerate(items):
            ref = full[(0, 9, last)[j]] if len(items) == 3 else default_collate([full[i] for i in (0, 9, last)])
            assert item[S.IMAGE].shape[-4] == 2  # the observed frames, no more
            assert torch.equal(item[S.IMAGE], ref[S.IMAGE][..., :2, :, :, :])
            assert torch.equal(item[S.ACTION], ref[S.ACTION]) and torch.equal(item[IS_PAD], ref[IS_PAD])
    for bad, match in [
        (dict(context_only=[S.FRAME_INDEX]), "every frame"),
        (dict(columns=[S.ACTION], context_only=[S.IMAGE]), "not in columns"),
        (dict(context_only=["observation.nothing"]), "not in the dataset"),
    ]:
        with pytest.raises(ValueError, match=match):
            load_windows(tiny_dataset_master, cache_dir=cache, **bad)


def test_image_size_resizes_rgb_by_area_and_depth_by_nearest(tiny_dataset_master, cache, reference):
    ds = load_windows(tiny_dataset_master, columns=[S.IMAGE, S.DEPTH], image_size=32, cache_dir=cache)
    item = ds[5]
    assert item[S.IMAGE].shape == (20, 3, 32, 32) and item[S.DEPTH].shape == (20, 32, 32)
    row = expected_rows(reference, item)[0]
    rgb = cv2.resize(reference[S.IMAGE][row].transpose(1, 2, 0), (32, 32), interpolation=cv2.INTER_AREA)
    np.testing.assert_array_equal(item[S.IMAGE][0].numpy(), rgb.transpose(2, 0, 1))
    depth = cv2.resize(reference[S.DEPTH][row], (32, 32), interpolation=cv2.INTER_NEAREST)
    np.testing.assert_array_equal(item[S.DEPTH][0].numpy(), depth)


def test_a_batch_decoded_in_place_equals_stacked_items(windows):
    indices = [0, 7, 100, 5, len(windows) - 1]
    batch = collate_windows(windows.__getitems__(indices))
    stacked = default_collate([windows[i] for i in indices])
    assert set(batch) == set(stacked)
    for name in batch:
        assert batch[name].shape == stacked[name].shape and batch[name].is_contiguous()
        assert torch.equal(batch[name], stacked[name]), name
    # Any collate function still gets a list of per-window dicts.
    assert torch.equal(default_collate(windows.__getitems__(indices))[S.IMAGE], stacked[S.IMAGE])


def test_index_errors_and_config_validation(windows):
    with pytest.raises(IndexError, match="out of range"):
        windows[len(windows)]
    assert torch.equal(windows[-1][S.FRAME_INDEX], windows[len(windows) - 1][S.FRAME_INDEX])
    for bad, match in [
        (dict(context=0), "context"),
        (dict(horizon=-1), "horizon"),
        (dict(stride=0), "stride"),
        (dict(image_size=0), "image_size"),
        (dict(columns="action"), "list of column"),
        (dict(context=2.5), r"context=2.5: give a whole number"),
        (dict(image_size=64.0), r"image_size=64.0: give a whole number"),
        (dict(stride=True), r"stride=True: give a whole number"),
        (dict(pad="no"), r"pad='no': give True or False"),
    ]:
        with pytest.raises(ValueError, match=match):
            WindowConfig(**bad)


def test_load_windows_refuses_one_string_for_a_list_of_columns(tiny_dataset_master):
    """Not a column named 'a', 'c', 't', ...: the string itself, with the fix."""
    from orbitdata import load_windows

    for key in ("columns", "context_only"):
        with pytest.raises(ValueError, match=rf"{key}='action': pass a list of column names, not one string"):
            load_windows(tiny_dataset_master, context=2, horizon=1, **{key: "action"})
