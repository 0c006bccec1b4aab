"""Rows of one Parquet file by row number, reading only the row groups that hold them.

Used wherever a few episodes are read out of a big shard: ``show`` and the episode reader,
the overview's sample frames, and re-sharding (which walks a file forwards, episode by episode).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq


def damaged(path: Path, exc: BaseException) -> ValueError:
    """The one-line error for a Parquet file pyarrow could not read: the file, why, and what to do."""
    why = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    return ValueError(
        f"{path} cannot be read ({why}): the file is damaged; run `orbitdata validate` on the dataset, then "
        "download or regenerate the files it names"
    )


def readable(read, path: Path):
    """``read()``, with pyarrow's errors on a damaged file turned into :func:`damaged`'s (a missing
    or forbidden file stays a FileNotFoundError or PermissionError)."""
    try:
        return read()
    except (FileNotFoundError, PermissionError):
        raise
    except (pa.ArrowException, OSError) as exc:
        raise damaged(path, exc) from None


class RowReader:
    """Rows [start, stop) or single cells of a Parquet file; row groups read once each.

    Row groups are cached until a read starts past them, so a forward walk (episodes in file
    order) holds only the groups it is in.
    """

    def __init__(self, path: Path, columns: list[str] | None = None, memory_map: bool = False):
        self.path = Path(path)
        self.file = readable(lambda: pq.ParquetFile(self.path, memory_map=memory_map), self.path)
        self.columns = columns
        sizes = [self.file.metadata.row_group(g).num_rows for g in range(self.file.num_row_groups)]
        self.starts = np.cumsum([0, *sizes])  # (G + 1,) first row of each group, then the row count
        self._cache: dict[int, pa.Table] = {}

    @property
    def num_rows(self) -> int:
        return int(self.starts[-1])

    def _group(self, g: int) -> pa.Table:
        if g not in self._cache:
            self._cache[g] = readable(lambda: self.file.read_row_group(g, columns=self.columns), self.path)
        return self._cache[g]

    def rows(self, start: int, stop: int) -> pa.Table:
        """Rows [start, stop) as one table."""
        if not 0 <= start < stop <= self.num_rows:
            raise ValueError(
                f"{self.path} has {self.num_rows} rows; rows {start}..{stop} are out of range. "
                "Run `orbitdata validate` on the dataset."
            )
        first = int(np.searchsorted(self.starts, start, side="right")) - 1
        last = int(np.searchsorted(self.starts, stop, side="left")) - 1
        for g in [g for g in self._cache if g < first]:
            del self._cache[g]
        table = pa.concat_tables([self._group(g) for g in range(first, last + 1)])
        return table.slice(start - int(self.starts[first]), stop - start)

    def cells(self, rows: list[int], column: str) -> list:
        """Values of ``column`` at the given rows (any order)."""
        out = []
        for r in rows:
            if not 0 <= r < self.num_rows:
                raise ValueError(
                    f"{self.path} has {self.num_rows} rows; row {r} is out of range. "
                    "Run `orbitdata validate` on the dataset."
                )
            g = int(np.searchsorted(self.starts, r, side="right")) - 1
            out.append(self._group(g).column(column)[int(r - self.starts[g])].as_py())
        return out


def read_rows(path: Path, start: int, stop: int, columns: list[str]) -> pa.Table:
    """Rows [start, stop) of a Parquet file, reading only the row groups that hold them."""
    return RowReader(path, columns).rows(start, stop)


def read_cells(path: Path, rows: list[int], column: str) -> list:
    """Values of ``column`` at the given rows of a Parquet file, reading each row group once."""
    return RowReader(path, [column]).cells(rows, column)
