"""Seed derivation. Every random draw in orbitdata comes from a generator made here.

An episode is a pure function of (root seed, episode index, config): its seed is derived
from the first two, and each consumer (scenario sampler, pilot noise, planner sampling)
gets its own independent stream of that seed, so adding a draw in one never shifts another.
"""

from __future__ import annotations

import numpy as np

STREAMS = {
    "scenario": 0,
    "pilot": 1,
    "planner": 2,
    "split": 3,
    "level": 4,
    "thrust-noise": 5,
    # the dynamic tier's draws (orbitdata.scenario.dynamic_sampler) and its camera noise (one draw per frame)
    "orbit": 6,
    "debris": 7,
    "body": 8,
    "fault": 9,
    "sensing": 10,
    "sensor-noise": 11,
}


def _fold(key: list[int]) -> int:
    """A 63-bit seed from a key of non-negative integers (SeedSequence's hash of it)."""
    hi, lo = np.random.SeedSequence(key).generate_state(2, dtype=np.uint32)
    return int((int(hi) << 32 | int(lo)) & ((1 << 63) - 1))


def episode_seed(root_seed: int, index: int) -> int:
    """A 63-bit seed for episode ``index`` of a dataset generated with ``root_seed``."""
    if root_seed < 0 or index < 0:
        raise ValueError(f"seeds and indices must be non-negative, got {root_seed}, {index}")
    return _fold([root_seed, index])


def rng(seed: int, stream: str, draw: int = 0) -> np.random.Generator:
    """The generator for one named stream of an episode seed. ``draw`` k > 0: the k-th other,
    independent generator of that stream (another draw of the same episode's randomness, e.g.
    another RRT* plan of the same task); 0 is the episode's own."""
    if draw < 0:
        raise ValueError(f"draw={draw}: give 0 (the episode's own stream) or a positive draw")
    return np.random.default_rng([int(seed), STREAMS[stream]] + ([int(draw)] if draw else []))


def grid_seed(root_seed: int, n_obstacles: int, speed: float, episode: int) -> int:
    """Seed of evaluation episode ``episode`` in grid cell (n_obstacles, speed m/s)."""
    return _fold([int(root_seed), int(n_obstacles), int(round(speed * 1000)), int(episode)])
