"""The window index: where every window starts, built from the key columns with numpy.

Episodes are found as runs of equal ``episode_index`` whose ``frame_index`` counts 0..L-1, so
the index is right whatever the order of the files, and a corrupt table is named, not sliced.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitdata.load.config import WindowConfig


@dataclass(frozen=True)
class Episodes:
    """The episodes of a steps table, in table order."""

    ids: np.ndarray  # (E,) int64 episode_index
    starts: np.ndarray  # (E,) int64 first row
    lengths: np.ndarray  # (E,) int64 frames


def find_episodes(episode_index: np.ndarray, frame_index: np.ndarray, where: str = "the steps table") -> Episodes:
    """Runs of one episode each; raises if an episode is split, reordered or has gaps."""
    episode_index = np.asarray(episode_index, dtype=np.int64)
    frame_index = np.asarray(frame_index, dtype=np.int64)
    n = len(episode_index)
    if n == 0:
        return Episodes(*(np.zeros(0, np.int64) for _ in range(3)))
    change = np.flatnonzero(episode_index[1:] != episode_index[:-1]) + 1
    starts = np.concatenate([[0], change]).astype(np.int64)
    lengths = np.diff(np.concatenate([starts, [n]])).astype(np.int64)
    ids = episode_index[starts]
    unique, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        bad = int(unique[counts > 1][0])
        raise ValueError(
            f"episode {bad} is split into several row ranges in {where}; rows must be ordered by "
            "(episode_index, frame_index) with each episode contiguous (run `orbitdata validate`)"
        )
    expected = np.arange(n, dtype=np.int64) - np.repeat(starts, lengths)
    wrong = np.flatnonzero(frame_index != expected)
    if len(wrong):
        row = int(wrong[0])
        raise ValueError(
            f"episode {int(episode_index[row])} in {where}: row {row} has frame_index {int(frame_index[row])}, "
            f"expected {int(expected[row])}; frames must count 0..L-1 in order (run `orbitdata validate`)"
        )
    return Episodes(ids=ids, starts=starts, lengths=lengths)


@dataclass(frozen=True)
class WindowIndex:
    """Window w covers rows ``row[w] .. row[w] + n_real[w] - 1``, then repeats its last row."""

    row: np.ndarray  # (N,) int64 first row in the steps table
    n_real: np.ndarray  # (N,) int32 real frames, <= T
    episode: np.ndarray  # (N,) int32 episode_index

    def __len__(self) -> int:
        return len(self.row)


def window_starts(lengths: np.ndarray, config: WindowConfig) -> tuple[np.ndarray, np.ndarray]:
    """(episode position, start frame) of every window, for episodes of these lengths."""
    lengths = np.asarray(lengths, dtype=np.int64)
    counts = np.maximum(0, (lengths - config.min_frames) // config.stride + 1)
    counts[lengths < config.min_frames] = 0
    which = np.repeat(np.arange(len(lengths)), counts)  # (N,)
    first = np.cumsum(counts) - counts
    start = (np.arange(counts.sum(), dtype=np.int64) - np.repeat(first, counts)) * config.stride
    return which, start


def build_index(episodes: Episodes, config: WindowConfig, keep: np.ndarray | None = None) -> WindowIndex:
    """Every window of the kept episodes (all when ``keep`` is None), in table order."""
    mask = np.ones(len(episodes.ids), bool) if keep is None else np.isin(episodes.ids, keep)
    lengths = np.where(mask, episodes.lengths, 0)
    which, start = window_starts(lengths, config)
    n_real = np.minimum(config.length, episodes.lengths[which] - start)
    return WindowIndex(
        row=episodes.starts[which] + start, n_real=n_real.astype(np.int32), episode=episodes.ids[which].astype(np.int32)
    )


class NoWindow(ValueError):
    """Every selected episode is shorter than one window; ``longest`` is the longest one's frames."""

    def __init__(self, message: str, longest: int):
        super().__init__(message)
        self.longest = longest


def check_windows(lengths: np.ndarray, config: WindowConfig, where: str) -> None:
    """Raise :class:`NoWindow` when episodes of these lengths give no window: every one is shorter than a window."""
    lengths = np.asarray(lengths, dtype=np.int64)
    if (lengths >= config.min_frames).any():
        return
    longest = int(lengths.max()) if len(lengths) else 0
    fix = "use a shorter context/horizon" + ("" if config.pad else ", or pad=True to pad the horizon")
    raise NoWindow(
        f"a window of {config.min_frames} real frames (context {config.context} + horizon {config.horizon}"
        f"{', horizon padded' if config.pad else ''}) is longer than every selected episode of {where} "
        f"(longest: {longest} frames); {fix}",
        longest,
    )


def check_lengths(found: Episodes, ids: np.ndarray, lengths: np.ndarray, where: str) -> None:
    """Raise unless each episode (``ids``, ``lengths`` from the episodes table) has that many rows."""
    position = {int(e): i for i, e in enumerate(found.ids)}
    for episode, length in zip(ids.tolist(), lengths.tolist()):
        i = position.get(episode)
        if i is None:
            raise ValueError(
                f"episode {episode} is in the episodes table but has no rows in {where}; run `orbitdata validate`"
            )
        if int(found.lengths[i]) != length:
            raise ValueError(
                f"episode {episode}: the episodes table says {length} frames but {where} has "
                f"{int(found.lengths[i])} rows for it; run `orbitdata validate`"
            )
