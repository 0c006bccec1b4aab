"""One episode of a local dataset: its row in the episodes table and its slice of a data shard.

Only the row groups that hold the episode are read; images stay encoded until asked for.
``orbitdata show``, the figures and closed-loop evaluation read episodes through this.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from orbitdata import schema as S
from orbitdata.codecs import decode_depth, decode_rgb
from orbitdata.load.rows import read_rows, readable
from orbitdata.load.source import dataset_folder
from orbitdata.scenario.spec import Scenario
from orbitdata.state import FUEL, POSITION, ROT6D, VELOCITY

STEP_COLUMNS = (S.FRAME_INDEX, S.EPISODE_INDEX, S.STATE, S.ACTION, S.COLLISION, S.SUCCESS, S.MIN_CLEARANCE)


def dynamics_record(row: dict) -> dict | None:
    """The dynamic tier's record (``dataclasses.asdict`` of a ``Dynamics``, for
    ``Scenario.from_dict``) from an episodes-table row; None for a static-tier row. Its numbers
    are the stored float32 values."""
    if S.DEBRIS_MOTION not in row:
        return None
    return {field: row[column] for field, column in S.DYNAMICS_COLUMNS.items()}


class EpisodeNotFound(ValueError):
    """The dataset holds no episode with that index."""


def episode_files(root: Path) -> list[Path]:
    """The episodes shards of a finished dataset folder, sorted."""
    root = dataset_folder(root)
    files = sorted(
        p for p in (root / S.EPISODES_DIR).glob("*.parquet") if S.SHARD_RE.match(p.relative_to(root).as_posix())
    )
    if not files:
        raise FileNotFoundError(f"{root} has no {S.EPISODES_DIR}/*.parquet shards; run `orbitdata validate {root}`")
    return files


def read_episodes(root: Path, columns: list[str] | None = None) -> pa.Table:
    """The episodes table of all splits, ordered by episode index."""
    files = episode_files(root)
    if columns is not None and files:
        names = readable(lambda: pq.read_schema(files[0]).names, files[0])
        missing = sorted(set(columns) - set(names))
        if missing:
            raise ValueError(f"columns {missing} are not in the episodes table of {root}: give some of {names}")
    table = pa.concat_tables([readable(lambda f=f: pq.read_table(f, columns=columns), f) for f in files])
    return table.sort_by(S.EPISODE_INDEX) if S.EPISODE_INDEX in table.column_names else table


def _index_range(indices: list[int]) -> str:
    if not indices:
        return "no episodes"
    lo, hi = min(indices), max(indices)
    if hi - lo + 1 == len(indices):
        return f"{len(indices)} episodes, indices {lo} to {hi}"
    return f"{len(indices)} episodes with indices between {lo} and {hi}, not contiguous"


def index_range(root: Path) -> str:
    """Which episode indices a dataset holds, in words (for messages)."""
    return _index_range(read_episodes(root, [S.EPISODE_INDEX]).column(S.EPISODE_INDEX).to_pylist())


@dataclass
class Episode:
    """One episode's metadata, trajectory and (still encoded) frames."""

    root: Path
    meta: dict  # its row of the episodes table
    steps: pa.Table  # its rows of the data table, without images

    @property
    def index(self) -> int:
        return self.meta[S.EPISODE_INDEX]

    def __len__(self) -> int:
        return self.steps.num_rows

    @cached_property
    def scenario(self) -> Scenario:
        """The episode's scenario, with its dynamic-tier record (``dynamics``) when it has one."""
        return Scenario.from_dict({**self.meta, "dynamics": dynamics_record(self.meta)})

    @cached_property
    def obstacle_poses(self) -> np.ndarray | None:
        """(L, N, 7) float32, privileged: each obstacle's centre (m, world) and quat (w, x, y, z) at
        every frame; None for a static-tier episode (its obstacles stand still)."""
        if S.DEBRIS_MOTION not in self.meta:
            return None
        m = self.meta
        rows = read_rows(self.root / m[S.DATA_FILE], m[S.ROW_START], m[S.ROW_END], [S.OBSTACLE_POSES])
        col = rows.column(S.OBSTACLE_POSES).combine_chunks()
        flat = col.flatten().flatten().to_numpy(zero_copy_only=False)
        return flat.astype(np.float32).reshape(len(col), m[S.N_OBSTACLES], 7)

    def _column(self, name: str) -> np.ndarray:
        col = self.steps.column(name).combine_chunks()
        if pa.types.is_fixed_size_list(col.type):
            return col.values.to_numpy(zero_copy_only=False).reshape(len(col), col.type.list_size)
        return col.to_numpy(zero_copy_only=False)

    @cached_property
    def states(self) -> np.ndarray:
        return self._column(S.STATE)  # (L, 16)

    @cached_property
    def actions(self) -> np.ndarray:
        return self._column(S.ACTION)  # (L, 8) thrust in [0, 1]

    @property
    def positions(self) -> np.ndarray:
        return self.states[:, POSITION]  # (L, 3) metres, world frame

    @property
    def camera_axis(self) -> np.ndarray:
        """(L, 3) world direction of the camera (body +x): the first column of R."""
        r = self.states[:, ROT6D]  # [R00, R01, R10, R11, R20, R21]
        return r[:, [0, 2, 4]]

    @property
    def speed(self) -> np.ndarray:
        return np.linalg.norm(self.states[:, VELOCITY], axis=1)  # (L,) m/s

    @property
    def fuel(self) -> np.ndarray:
        return self.states[:, FUEL][:, 0]  # (L,) ratio

    @cached_property
    def clearance(self) -> np.ndarray:
        return self._column(S.MIN_CLEARANCE)  # (L,) metres

    @property
    def times(self) -> np.ndarray:
        return np.arange(len(self), dtype=float) * S.DT  # (L,) seconds

    @property
    def collision_at(self) -> np.ndarray | None:
        """Where the CubeSat was when it touched an obstacle (its last position), or None."""
        return self.positions[-1] if self.meta[S.OUTCOME] == "collision" else None

    def title(self) -> str:
        m = self.meta
        return (
            f"episode {self.index} · {m[S.SPLIT]} · {m[S.LEVEL]} pilot · {m[S.OUTCOME]} · "
            f"{m[S.N_OBSTACLES]} obstacle{'s' if m[S.N_OBSTACLES] != 1 else ''} · "
            f"{len(self)} frames ({len(self) * S.DT:.1f} s)"
        )

    # ---- frames (decoded on demand) ---------------------------------------------------------
    def encoded(self, column: str, frames=None) -> list[bytes]:
        """The stored bytes of an image column (JPEG / PNG), all frames or those at the given indices."""
        return self._encoded(column, self._frames(frames))

    def _encoded(self, column: str, frames) -> list[bytes]:
        m = self.meta
        rows = read_rows(self.root / m[S.DATA_FILE], m[S.ROW_START], m[S.ROW_END], [column])
        col = rows.column(column).combine_chunks().field("bytes")
        return [col[int(t)].as_py() for t in frames]

    def rgb(self, frames=None) -> list[np.ndarray]:
        """RGB frames (H, W, 3) uint8, all of them or those at the given indices."""
        return [decode_rgb(b) for b in self._encoded(S.IMAGE, self._frames(frames))]

    def depth(self, frames=None) -> list[np.ndarray]:
        """Depth frames (H, W) float32 metres, 0 = no return."""
        return [decode_depth(b) for b in self._encoded(S.DEPTH, self._frames(frames))]

    def _frames(self, frames) -> list[int]:
        if frames is None:
            return list(range(len(self)))
        frames = [int(t) for t in frames]
        bad = [t for t in frames if not 0 <= t < len(self)]
        if bad:
            raise ValueError(f"frame(s) {bad} out of range for episode {self.index} with {len(self)} frames")
        return frames


def load_episode(root: Path, index: int) -> Episode:
    """Episode ``index`` (its ``episode_index``, unique across splits) of the dataset at ``root``."""
    root = dataset_folder(root)
    table = read_episodes(root)
    indices = table.column(S.EPISODE_INDEX).to_pylist()
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index not in indices:
        raise EpisodeNotFound(
            f"episode {index!r} is not in {root}: it holds {_index_range(indices)}; "
            "pick one of those (`orbitdata info` lists the counts)"
        )
    meta = table.slice(indices.index(index), 1).to_pylist()[0]
    data = root / meta[S.DATA_FILE]
    if not data.exists():
        raise FileNotFoundError(
            f"{data} (the data shard of episode {index}) is missing; "
            "re-download the dataset or run `orbitdata validate`"
        )
    steps = read_rows(data, meta[S.ROW_START], meta[S.ROW_END], list(STEP_COLUMNS))
    ep_col = steps.column(S.EPISODE_INDEX).to_numpy()
    frame_col = steps.column(S.FRAME_INDEX).to_numpy()
    if len(steps) != meta[S.LENGTH] or (ep_col != index).any() or (frame_col != np.arange(len(steps))).any():
        raise ValueError(
            f"rows {meta[S.ROW_START]}..{meta[S.ROW_END]} of {meta[S.DATA_FILE]} are not episode {index}'s "
            f"{meta[S.LENGTH]} frames in order; the dataset is inconsistent: run `orbitdata validate`"
        )
    return Episode(root, meta, steps)
