"""A block of consecutive steps rows as numpy arrays: what the row checks work on.

Built from one Parquet row group. Nulls never crash the checks: they become NaN (floats) or
-1 (indices) and are reported by ``values.finite``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import pyarrow as pa

from orbitdata import schema as S


def fixed_list(column: pa.ChunkedArray, width: int) -> np.ndarray:
    """(N, width) float64 of a fixed-size-list column; null lists and null values become NaN."""
    arr = column.combine_chunks()
    n = len(arr)
    values = arr.values.slice(arr.offset * width, n * width)
    out = values.to_numpy(zero_copy_only=False).astype(np.float64).reshape(n, width)
    if arr.null_count:
        out[~np.asarray(arr.is_valid())] = np.nan
    return out


def _scalar(column: pa.ChunkedArray, dtype, fill) -> np.ndarray:
    arr = column.combine_chunks()
    if arr.null_count:
        arr = arr.fill_null(fill)
    return arr.to_numpy(zero_copy_only=False).astype(dtype)


@dataclass
class Frames:
    row: np.ndarray  # (N,) int64 row number within the file
    episode: np.ndarray  # (N,) int64
    frame: np.ndarray  # (N,) int64
    timestamp: np.ndarray  # (N,) float64 seconds
    state: np.ndarray  # (N, 16) float64
    action: np.ndarray  # (N, 8) float64 normalised thrust
    collision: np.ndarray  # (N,) bool
    success: np.ndarray  # (N,) bool
    is_last: np.ndarray  # (N,) bool
    clearance: np.ndarray  # (N,) float64 metres

    def __len__(self) -> int:
        return len(self.row)

    def take(self, index) -> "Frames":
        return Frames(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @classmethod
    def concat(cls, parts: list["Frames"]) -> "Frames":
        return cls(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)})

    @classmethod
    def from_table(cls, table: pa.Table, first_row: int) -> "Frames":
        n = table.num_rows
        return cls(
            row=np.arange(first_row, first_row + n, dtype=np.int64),
            episode=_scalar(table.column(S.EPISODE_INDEX), np.int64, -1),
            frame=_scalar(table.column(S.FRAME_INDEX), np.int64, -1),
            timestamp=_scalar(table.column(S.TIMESTAMP), np.float64, float("nan")),
            state=fixed_list(table.column(S.STATE), S.STATE_DIM),
            action=fixed_list(table.column(S.ACTION), S.ACTION_DIM),
            collision=_scalar(table.column(S.COLLISION), bool, False),
            success=_scalar(table.column(S.SUCCESS), bool, False),
            is_last=_scalar(table.column(S.IS_LAST), bool, False),
            clearance=_scalar(table.column(S.MIN_CLEARANCE), np.float64, float("nan")),
        )


def null_columns(table: pa.Table) -> dict[str, np.ndarray]:
    """Column name -> row indices (within the table) holding a null."""
    out = {}
    for name in table.column_names:
        col = table.column(name)
        if col.null_count:
            if name in S.IMAGE_COLUMNS:
                continue  # an image struct may carry a null path; its bytes are checked by images.decode
            out[name] = np.flatnonzero(~np.asarray(col.combine_chunks().is_valid()))
    return out
