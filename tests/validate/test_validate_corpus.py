"""The corruption corpus: every check of `orbitdata validate` catches its own kind of damage.

Each case breaks a private copy of the tiny generated dataset in one way and names the check
that must report it (and, where the damage has one, the episode and frame it must name).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import corruptions as X
import numpy as np
import pyarrow as pa
import pytest

from orbitdata import schema as S
from orbitdata.validate import CHECKS, ValidateOptions, validate
from orbitdata.validate import checks as C


@dataclass(frozen=True)
class Case:
    name: str
    check: str
    corrupt: Callable[[Path], tuple[int, int] | None]  # returns (episode, frame) the report must name
    quick: bool = False  # also caught by --quick
    only: bool = False  # the only failing check (reseal'd cases that touch nothing else)


def _delete(rel):
    return lambda root: (root / rel).unlink()


def _extra(root):
    (root / S.DATA_DIR / "notes.txt").write_text("scratch")


def _broken_link(root):
    (root / "junk").symlink_to(root / "nowhere")


def _parts_leftover(root):
    (root / S.PARTS_DIR).mkdir()
    (root / S.PARTS_DIR / "unit-00000.steps.parquet").write_bytes(b"x")


def _bad_json(root):
    (root / S.STATS_PATH).write_text("{not json")


def _bad_card_yaml(root):
    text = (root / S.CARD_PATH).read_text()
    (root / S.CARD_PATH).write_text(text.replace("license:", "license: [unclosed", 1))


def _truncate(root):
    path = root / X.TEST
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _bad_footer(root):
    path = root / X.TEST
    data = bytearray(path.read_bytes())
    data[-8:-4] = b"\xff\xff\xff\x7f"  # footer length beyond the file
    path.write_bytes(bytes(data))


def _bad_page(root):
    """Garbage over the page header of one column chunk; the footer stays intact."""
    path = root / X.TRAIN
    offset = X.page_offset(root, X.TRAIN, 2, S.STATE)
    data = bytearray(path.read_bytes())
    data[offset : offset + 24] = b"\xde\xad\xbe\xef" * 6
    path.write_bytes(bytes(data))
    X.reseal(root, X.TRAIN)


def _sha(root):
    with open(root / X.TRAIN, "ab") as f:
        f.write(b"\0")  # Parquet readers ignore nothing: but the hash must catch it first


def _card_edit(root):
    with open(root / S.CARD_PATH, "a") as f:
        f.write("\nedited by hand\n")


def _rename_column(root):
    table = X.read(root, X.TRAIN)
    names = [("actions" if n == S.ACTION else n) for n in table.column_names]
    X.write(
        root,
        X.TRAIN,
        table.rename_columns(names),
        schema=table.schema.remove_metadata().set(
            table.schema.get_field_index(S.ACTION), pa.field("actions", table.schema.field(S.ACTION).type)
        ),
    )


def _wrong_type(root):
    table = X.read(root, X.TRAIN)
    i = table.schema.get_field_index(S.FRAME_INDEX)
    table = table.set_column(i, S.FRAME_INDEX, table.column(S.FRAME_INDEX).cast(pa.int64()))
    X.write(root, X.TRAIN, table, schema=table.schema)


def _wrong_width(root):
    table = X.read(root, X.TEST)
    state = X.matrix(table, S.STATE, S.STATE_DIM)[:, :15]
    arr = pa.FixedSizeListArray.from_arrays(pa.array(state.reshape(-1)), 15)
    table = table.set_column(table.schema.get_field_index(S.STATE), S.STATE, arr)
    X.write(root, X.TEST, table, schema=table.schema)


def _version(root):
    X.edit_json(root, S.INFO_PATH, lambda info: info.update(schema_version="9.9"))


def _drop_row(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    row = ep[S.ROW_START] + 20
    X.write(root, X.TRAIN, pa.concat_tables([table.slice(0, row), table.slice(row + 1)]))
    return ep[S.EPISODE_INDEX], 21


def _duplicate_row(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    row = ep[S.ROW_START] + 30
    X.write(root, X.TRAIN, pa.concat_tables([table.slice(0, row + 1), table.slice(row)]))
    return ep[S.EPISODE_INDEX], 30


def _swap_rows(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    row = ep[S.ROW_START] + 40
    order = np.arange(table.num_rows)
    order[[row, row + 1]] = order[[row + 1, row]]
    X.write(root, X.TRAIN, table.take(pa.array(order)))
    return ep[S.EPISODE_INDEX], 40


def _timestamp(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    ts = X.scalars(table, S.TIMESTAMP)
    ts[ep[S.ROW_START] + 12] += 0.013
    X.write(root, X.TRAIN, X.set_scalar(table, S.TIMESTAMP, ts))
    return ep[S.EPISODE_INDEX], 12


def _unset_is_last(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    flags = X.scalars(table, S.IS_LAST)
    flags[ep[S.ROW_END] - 1] = False
    X.write(root, X.TRAIN, X.set_scalar(table, S.IS_LAST, flags))
    return ep[S.EPISODE_INDEX], ep[S.LENGTH] - 1


def _length(root):
    table = X.read(root, X.TEST_EPISODES)
    lengths = X.scalars(table, S.LENGTH)
    lengths[0] += 1
    table = X.set_scalar(table, S.LENGTH, lengths)
    X.write(root, X.TEST_EPISODES, table)


def _level(root):
    table = X.read(root, X.TRAIN_EPISODES)
    X.write(root, X.TRAIN_EPISODES, X.set_scalar(table, S.LEVEL, ["pro"] + table.column(S.LEVEL).to_pylist()[1:]))


def _duplicate_index(root):
    table = X.read(root, X.TRAIN_EPISODES)
    index = X.scalars(table, S.EPISODE_INDEX)
    index[1] = index[0]
    X.write(root, X.TRAIN_EPISODES, X.set_scalar(table, S.EPISODE_INDEX, index))


def _episode_in_both_splits(root):
    train = X.read(root, X.TRAIN_EPISODES)
    test = X.read(root, X.TEST_EPISODES)
    index = X.scalars(test, S.EPISODE_INDEX)
    index[0] = train.column(S.EPISODE_INDEX)[0].as_py()
    X.write(root, X.TEST_EPISODES, X.set_scalar(test, S.EPISODE_INDEX, index))


def _seed_in_both_splits(root):
    train = X.read(root, X.TRAIN_EPISODES)
    test = X.read(root, X.TEST_EPISODES)
    seeds = X.scalars(test, S.SEED)
    seeds[0] = train.column(S.SEED)[0].as_py()
    X.write(root, X.TEST_EPISODES, X.set_scalar(test, S.SEED, seeds))


def _collision_mid_episode(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    flags = X.scalars(table, S.COLLISION)
    flags[ep[S.ROW_START] + 50] = True
    X.write(root, X.TRAIN, X.set_scalar(table, S.COLLISION, flags))
    return ep[S.EPISODE_INDEX], 50


def _state_edit(offset: int, fn, split: str = "train"):
    """Edit one state; test-split edits leave meta/stats.json (train only) right."""

    def corrupt(root):
        ep = X.longest_episode(root, split)
        X.edit_state(root, ep[S.DATA_FILE], ep[S.ROW_START] + offset, fn)
        return ep[S.EPISODE_INDEX], offset

    return corrupt


def _nan_action(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    a = X.matrix(table, S.ACTION, S.ACTION_DIM)
    a[ep[S.ROW_START] + 7, 3] = np.inf
    X.write(root, X.TRAIN, X.set_matrix(table, S.ACTION, a))
    return ep[S.EPISODE_INDEX], 7


def _action(value: float, offset: int | None, split: str = "train"):
    def corrupt(root):
        ep = X.longest_episode(root, split)
        frame = ep[S.LENGTH] - 1 if offset is None else offset
        table = X.read(root, ep[S.DATA_FILE])
        a = X.matrix(table, S.ACTION, S.ACTION_DIM)
        a[ep[S.ROW_START] + frame, 0] = value
        X.write(root, ep[S.DATA_FILE], X.set_matrix(table, S.ACTION, a))
        return ep[S.EPISODE_INDEX], frame

    return corrupt


def _rotate(angle):
    def fn(s):
        R = np.array(s[6:12]).reshape(3, 2)
        s[6:12] = (X.rotation_z(angle) @ np.c_[R, np.cross(R[:, 0], R[:, 1])])[:, :2].reshape(-1)

    return fn


def _clearance(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    c = X.scalars(table, S.MIN_CLEARANCE)
    c[ep[S.ROW_START] + 9] = -0.2
    X.write(root, X.TRAIN, X.set_scalar(table, S.MIN_CLEARANCE, c))
    return ep[S.EPISODE_INDEX], 9


def _image(column: str, blob: Callable[[Path], bytes], offset: int = 15):
    def corrupt(root):
        ep = X.longest_train_episode(root)
        X.set_image(root, X.TRAIN, column, ep[S.ROW_START] + offset, blob(root))
        return ep[S.EPISODE_INDEX], offset

    return corrupt


def _far_depth(root):
    depth = np.zeros((64, 64), np.uint16)
    depth[10:20, 10:20] = 60000  # 60 m: beyond the 50.1 m far plane
    return X.png(depth)


def _depth_low(root):
    ep = X.longest_train_episode(root)
    table = X.read(root, X.TRAIN)
    low = X.matrix(table, S.DEPTH_LOW, S.DEPTH_LOW_DIM)
    low[ep[S.ROW_START] + 25, 100] += 0.5
    X.write(root, X.TRAIN, X.set_matrix(table, S.DEPTH_LOW, low))
    return ep[S.EPISODE_INDEX], 25


def _card_count(root):
    text = (root / S.CARD_PATH).read_text()
    frames = json.loads((root / S.INFO_PATH).read_text())["counts"]["splits"]["train"]["frames"]
    (root / S.CARD_PATH).write_text(text.replace(f"num_examples: {frames}", f"num_examples: {frames + 7}", 1))
    X.reseal(root, S.CARD_PATH)


def _info_count(root):
    X.edit_json(
        root,
        S.INFO_PATH,
        lambda info: info["counts"]["splits"]["test"]["levels"]["expert"]["outcomes"].update(success=99),
    )


def _stats_mean(root):
    X.edit_json(root, S.STATS_PATH, lambda st: st[S.STATE]["mean"].__setitem__(3, st[S.STATE]["mean"][3] + 0.05))


def _stats_quantile(root):
    X.edit_json(root, S.STATS_PATH, lambda st: st[S.ACTION]["q99"].__setitem__(2, st[S.ACTION]["min"][2]))


CASES = [
    Case("deleted test shard", C.MISSING, _delete(X.TEST), quick=True),
    Case("deleted stats.json", C.MISSING, _delete(S.STATS_PATH), quick=True),
    Case("stray file", C.EXTRA, _extra, quick=True, only=True),
    Case("leftover parts/", C.EXTRA, _parts_leftover, quick=True, only=True),
    Case("stats.json not JSON", C.UNREADABLE, _bad_json, quick=True),
    Case("card YAML broken", C.UNREADABLE, _bad_card_yaml, quick=True),
    Case("a link to nothing", C.UNREADABLE, _broken_link, quick=True, only=True),
    Case("truncated shard", C.CORRUPT, _truncate, quick=True),
    Case("bad footer", C.CORRUPT, _bad_footer, quick=True),
    Case("bad data page", C.CORRUPT, _bad_page),
    Case("appended byte", C.SHA256, _sha, quick=True),
    Case("card edited", C.SHA256, _card_edit, quick=True, only=True),
    Case("renamed column", C.COLUMNS, _rename_column, quick=True),
    Case("int64 frame_index", C.COLUMNS, _wrong_type, quick=True),
    Case("state of 15 floats", C.COLUMNS, _wrong_width, quick=True),
    Case("unknown schema version", C.VERSION, _version, quick=True, only=True),
    Case("missing frame", C.FRAMES, _drop_row),
    Case("duplicated frame", C.FRAMES, _duplicate_row),
    Case("swapped frames", C.FRAMES, _swap_rows),
    Case("timestamp off the grid", C.TIMESTAMPS, _timestamp),
    Case("is_last unset", C.LENGTHS, _unset_is_last),
    Case("length disagrees with rows", C.LENGTHS, _length, quick=True),
    Case("unknown level", C.TABLE, _level, quick=True),
    Case("duplicate episode_index", C.DUPLICATES, _duplicate_index, quick=True),
    Case("episode in both splits", C.LEAK, _episode_in_both_splits, quick=True),
    Case("seed in both splits", C.LEAK, _seed_in_both_splits, quick=True, only=True),
    Case("collision mid-episode", C.EVENTS, _collision_mid_episode),
    Case("NaN in state", C.FINITE, _state_edit(33, lambda s: s.__setitem__(4, np.nan))),
    Case("Inf in action", C.FINITE, _nan_action),
    Case("action above 1", C.ACTION, _action(1.5, 44)),
    Case("terminal action not zero", C.ACTION, _action(0.3, None, "test"), only=True),
    Case("rot6d column scaled", C.ROT6D, _state_edit(60, lambda s: s.__setitem__(slice(6, 12), s[6:12] * 1.1))),
    Case("fuel above 1", C.FUEL, _state_edit(0, lambda s: s.__setitem__(15, 1.2))),
    Case("fuel rises", C.FUEL, _state_edit(80, lambda s: s.__setitem__(15, s[15] + 0.01), "test"), only=True),
    Case("start off origin", C.START, _state_edit(0, lambda s: s.__setitem__(0, 0.25))),
    Case("negative clearance", C.CLEARANCE, _clearance),
    Case("position jump", C.KIN_POSITION, _state_edit(70, lambda s: s.__setitem__(1, s[1] + 0.02))),
    Case("velocity sign flip", C.KIN_POSITION, _state_edit(90, lambda s: s.__setitem__(slice(3, 6), -s[3:6]))),
    Case("attitude jump", C.KIN_ROTATION, _state_edit(100, _rotate(0.05))),
    Case(
        "angular velocity scaled",
        C.KIN_ROTATION,
        _state_edit(110, lambda s: s.__setitem__(slice(12, 15), 3 * s[12:15] + 1)),
    ),
    Case("garbage JPEG", C.DECODE, _image(S.IMAGE, lambda root: b"\xff\xd8not a jpeg")),
    Case("garbage PNG", C.DECODE, _image(S.DEPTH, lambda root: b"\x89PNG broken")),
    Case("truncated JPEG", C.DECODE, _image(S.IMAGE, lambda root: X.image_bytes(root, X.TRAIN, S.IMAGE, 3)[:300])),
    Case("truncated PNG", C.DECODE, _image(S.DEPTH, lambda root: X.image_bytes(root, X.TRAIN, S.DEPTH, 3)[:-40])),
    Case("RGB of 32 px", C.SIZE, _image(S.IMAGE, lambda root: X.jpeg(np.zeros((32, 32, 3), np.uint8)))),
    Case("grey RGB PNG", C.SIZE, _image(S.IMAGE, lambda root: X.png(np.zeros((64, 64), np.uint8)))),
    Case("grey RGB JPEG", C.SIZE, _image(S.IMAGE, lambda root: X.jpeg(np.zeros((64, 64), np.uint8)))),
    Case("8-bit depth", C.SIZE, _image(S.DEPTH, lambda root: X.png(np.zeros((64, 64), np.uint8)))),
    Case("depth beyond far", C.DEPTH_RANGE, _image(S.DEPTH, _far_depth)),
    Case("depth_low edited", C.DEPTH_LOW, _depth_low),
    Case("card count", C.COUNTS, _card_count, quick=True, only=True),
    Case("info.json count", C.COUNTS, _info_count, quick=True, only=True),
    Case("stats mean", C.STATS, _stats_mean, only=True),
    Case("stats quantile", C.STATS, _stats_quantile, only=True),
]


def test_corpus_covers_every_check():
    assert {c.name for c in CHECKS} <= {case.check for case in CASES}


def test_clean_dataset_passes(tiny_dataset_master):
    for quick in (True, False):
        report = validate(tiny_dataset_master, ValidateOptions(quick=quick, workers=1))
        assert report.ok, report.render()
        assert report.frames > 0 and report.episodes == 6


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_corruption_is_detected(case: Case, tiny_dataset):
    where = case.corrupt(tiny_dataset)
    report = validate(tiny_dataset, ValidateOptions(workers=1))
    assert case.check in report.failed(), report.render()
    if case.only:
        assert report.failed() == [case.check], report.render()
    if where is not None:
        episode, frame = where
        located = [(f.episode, f.frame) for f in report.findings(case.check)]
        assert (episode, frame) in located, report.render()
        assert all(f.file for f in report.findings(case.check))
    quick = validate(tiny_dataset, ValidateOptions(quick=True, workers=1))
    if case.quick:
        assert case.check in quick.failed(), quick.render()
    else:
        assert case.check not in quick.failed()
