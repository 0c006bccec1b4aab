"""The episode plan: which level, split and seed every episode index gets, and the work units.

The plan depends only on the config (root seed, counts, mix), never on the number of
workers, so every execution (1 or N processes, local or Ray) produces the same episodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitdata.config import DatasetConfig
from orbitdata.schema import LEVELS
from orbitdata.seeding import episode_seed, rng


@dataclass(frozen=True)
class EpisodeTask:
    index: int
    split: str
    level: str
    seed: int


@dataclass(frozen=True)
class Unit:
    """A batch of consecutive episodes written to one part file (the resume granularity)."""

    index: int
    episodes: tuple[EpisodeTask, ...]

    @property
    def name(self) -> str:
        return f"unit-{self.index:05d}"


def _largest_remainder(total: int, shares) -> list[int]:
    shares = np.asarray(shares, dtype=np.float64)
    exact = shares / shares.sum() * total
    counts = np.floor(exact).astype(int)
    order = np.argsort(-(exact - counts), kind="stable")
    counts[order[: total - counts.sum()]] += 1
    return counts.tolist()


def plan_episodes(cfg: DatasetConfig) -> list[EpisodeTask]:
    """Levels in the configured proportions, shuffled; per level a stratified test share.

    A dataset too small for any level's share to round to one test episode still gets one (drawn
    from the split stream after the levels' shares, so larger plans are unchanged), as long as a
    test share is asked for and one episode is left to train on. A test share so large that it
    takes every episode leaves one to train on (drawn the same way).
    """
    n = cfg.episodes
    counts = _largest_remainder(n, cfg.level_mix)
    labels = np.repeat(np.arange(len(LEVELS)), counts)
    labels = labels[rng(cfg.seed, "level").permutation(n)]
    split = np.array(["train"] * n, dtype=object)
    split_rng = rng(cfg.seed, "split")
    for level in range(len(LEVELS)):
        members = np.flatnonzero(labels == level)
        n_test = int(round(len(members) * cfg.test_fraction))
        split[split_rng.permutation(members)[:n_test]] = "test"
    if cfg.test_fraction > 0 and n >= 2 and not (split == "test").any():
        split[int(split_rng.integers(n))] = "test"
    if n and not (split == "train").any():  # a test share so large it took every episode: keep one to train on
        split[int(split_rng.integers(n))] = "train"
    return [
        EpisodeTask(index=i, split=str(split[i]), level=LEVELS[labels[i]], seed=episode_seed(cfg.seed, i))
        for i in range(n)
    ]


def plan_units(cfg: DatasetConfig) -> list[Unit]:
    tasks = plan_episodes(cfg)
    k = cfg.episodes_per_unit
    return [Unit(index=u, episodes=tuple(tasks[i : i + k])) for u, i in enumerate(range(0, len(tasks), k))]
