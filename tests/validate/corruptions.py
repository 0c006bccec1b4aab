"""Ways to break a tiny generated dataset, one contract rule at a time.

Each corruption edits a private copy in place. ``reseal`` recomputes the sha256 and size of the
files it touched in meta/info.json, so that a case trips only the check it is about (and not
``files.sha256`` as well), as a careless tool that rewrites meta would.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from orbitdata import schema as S
from orbitdata.info import sha256_file

TRAIN = S.shard_path(S.DATA_DIR, "train", 0, 1)
TEST = S.shard_path(S.DATA_DIR, "test", 0, 1)
TRAIN_EPISODES = S.shard_path(S.EPISODES_DIR, "train", 0, 1)
TEST_EPISODES = S.shard_path(S.EPISODES_DIR, "test", 0, 1)
ROW_GROUP_ROWS = 64  # tests/conftest.py tiny_config


def reseal(root: Path, *rels: str) -> None:
    info_path = root / S.INFO_PATH
    info = json.loads(info_path.read_text())
    for rel in rels:
        info["files"][rel] = {"sha256": sha256_file(root / rel), "bytes": (root / rel).stat().st_size}
    info_path.write_text(json.dumps(info, indent=2, sort_keys=True) + "\n")


def edit_json(root: Path, rel: str, fn: Callable[[dict], None], seal: bool = True) -> None:
    data = json.loads((root / rel).read_text())
    fn(data)
    (root / rel).write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    if seal and rel != S.INFO_PATH:
        reseal(root, rel)


def read(root: Path, rel: str) -> pa.Table:
    return pq.read_table(root / rel)


def write(root: Path, rel: str, table: pa.Table, seal: bool = True, schema: pa.Schema | None = None) -> None:
    """Write like the generator (same row groups, codec, HF metadata); optionally reseal."""
    kind = rel.split("/")[0]
    if schema is None:
        schema = S.with_hf_metadata(S.STEP_SCHEMA if kind == S.DATA_DIR else S.EPISODE_SCHEMA, kind)
    pq.write_table(
        table.cast(schema) if schema.names == table.schema.names else table,
        root / rel,
        compression="zstd",
        row_group_size=ROW_GROUP_ROWS,
    )
    if seal:
        reseal(root, rel)


def episode(root: Path, index: int) -> dict:
    for rel in (TRAIN_EPISODES, TEST_EPISODES):
        for row in read(root, rel).to_pylist():
            if row[S.EPISODE_INDEX] == index:
                return row
    raise KeyError(index)


def longest_train_episode(root: Path) -> dict:
    return longest_episode(root, "train")


def longest_episode(root: Path, split: str) -> dict:
    rel = TRAIN_EPISODES if split == "train" else TEST_EPISODES
    return max(read(root, rel).to_pylist(), key=lambda r: r[S.LENGTH])


# ---- column edits -----------------------------------------------------------------------------
def matrix(table: pa.Table, name: str, width: int) -> np.ndarray:
    col = table.column(name).combine_chunks()
    return col.flatten().to_numpy(zero_copy_only=False).reshape(len(col), width).copy()


def set_matrix(table: pa.Table, name: str, values: np.ndarray) -> pa.Table:
    width = values.shape[1]
    arr = pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1).astype(np.float32)), width)
    return table.set_column(table.schema.get_field_index(name), name, arr)


def set_scalar(table: pa.Table, name: str, values) -> pa.Table:
    arr = pa.array(values, type=table.schema.field(name).type)
    return table.set_column(table.schema.get_field_index(name), name, arr)


def scalars(table: pa.Table, name: str) -> np.ndarray:
    return table.column(name).to_numpy(zero_copy_only=False).copy()


def edit_state(root: Path, rel: str, row: int, fn: Callable[[np.ndarray], None]) -> None:
    table = read(root, rel)
    state = matrix(table, S.STATE, S.STATE_DIM)
    fn(state[row])
    write(root, rel, set_matrix(table, S.STATE, state))


def set_image(root: Path, rel: str, column: str, row: int, blob: bytes) -> None:
    table = read(root, rel)
    col = table.column(column).combine_chunks()
    blobs = col.field("bytes").to_pylist()
    blobs[row] = blob
    arr = pa.StructArray.from_arrays(
        [pa.array(blobs, pa.binary()), pa.nulls(len(blobs), pa.string())], names=["bytes", "path"]
    )
    write(root, rel, table.set_column(table.schema.get_field_index(column), column, arr))


def image_bytes(root: Path, rel: str, column: str, row: int) -> bytes:
    return read(root, rel).column(column).combine_chunks().field("bytes")[row].as_py()


def jpeg(pixels: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", pixels)
    assert ok
    return buf.tobytes()


def png(pixels: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", pixels)
    assert ok
    return buf.tobytes()


def rotation_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def page_offset(root: Path, rel: str, row_group: int, column: str) -> int:
    md = pq.ParquetFile(root / rel).metadata.row_group(row_group)
    for i in range(md.num_columns):
        col = md.column(i)
        if col.path_in_schema == column or col.path_in_schema.startswith(column + "."):
            return col.data_page_offset
    raise KeyError(column)
