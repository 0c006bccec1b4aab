"""Lockstep flights: several grid episodes flown side by side, one batched pilot call per control step.

``orbitmodel eval closed-loop --batch N`` flies N episodes at once, each in a CubeSatEnv of its
own in this process and with a pilot of its own (``pilot.fork()``: the per-episode state, such as
the planner's MPPI nominal, point memory and latent history, or the policy's chunk queue). At
every control step one ``act_batch`` call serves all the live episodes, so the world model (or
the policy's denoiser) sees N times the batch. An episode that ends drops out; the next grid
episode, in grid order, takes its slot at the next step on the pilot's ``board_every`` clock (the
policy's chunk length: every episode then samples its chunks at the same steps, in one pass,
instead of a few at each step). Every episode draws from its own seeded generators, so
its flight does not depend on the batch it flew in apart from the float reduction order of the
batched calls; with N = 1 it is exactly the unbatched flight (``orbitdata.fly.rollout.fly_episode``).

The grid's episodes are flown in :func:`chunks` of consecutive episodes, each chunk on its own
(one after another here, or as Ray tasks, ``evaluate.executors``): which episodes share a batch
depends only on the grid and N, so a grid flown on Ray is the grid flown here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from orbitdata.fly.rollout import EpisodeResult, Flight
from orbitdata.sim.env import CubeSatEnv

ROUNDS_PER_CHUNK = 8  # a chunk holds this many batches' worth of episodes


class GridEpisode(NamedTuple):
    """One episode of the grid: its setting, its index in the setting, its seed."""

    obstacles: int
    speed: float
    episode: int
    seed: int


@dataclass
class FlownEpisode:
    """One episode as a chunk returns it: its place in the flight order, its record, its pilot's latency."""

    index: int
    record: dict
    step_ms: list[float]
    replan_ms: list[float]


@dataclass
class ChunkResult:
    part: range  # the chunk: its episodes' places in the flight order
    episodes: list[FlownEpisode]
    timings: dict[str, float]  # seconds per phase, summed over the chunk


# landed(index in the episodes given, result, pilot that flew it, rendered frames or None)
Landed = Callable[[int, EpisodeResult, object, "list[np.ndarray] | None"], None]


def chunks(total: int, batch: int) -> list[range]:
    """The grid's episodes 0..total-1 (in flight order) in consecutive parts of
    ``ROUNDS_PER_CHUNK * batch`` episodes: the unit of work, flown alike here and on Ray."""
    size = ROUNDS_PER_CHUNK * batch
    return [range(start, min(start + size, total)) for start in range(0, total, size)]


def fly_lockstep(
    pilot,
    make_env: Callable[[], CubeSatEnv],
    episodes: list[GridEpisode],
    batch: int,
    landed: Landed,
    image_quality: int | None = None,
    keep_frames: bool = False,
) -> None:
    """Fly ``episodes`` with up to ``batch`` at a time, calling ``landed`` as each one ends.

    ``pilot`` flies the first slot and its forks the others; a pilot without ``act_batch`` acts
    for each episode in turn. A freed slot takes the next episode at the next step that is a
    multiple of the pilot's ``board_every`` (1 when it has none), so that episodes whose pilots
    work on a period (the policy's chunks) keep in phase. ``image_quality`` as ``fly_episode``'s;
    ``keep_frames``: hand ``landed`` each episode's rendered frames (for videos)."""
    n = min(batch, len(episodes))
    if n < 1:
        return
    if n > 1 and not hasattr(pilot, "fork"):
        raise ValueError(f"pilot {pilot.name!r} flies one episode at a time: fly it with batch 1")
    pilots = [pilot] + [pilot.fork() for _ in range(n - 1)]
    envs: list[CubeSatEnv] = []
    act_batch = getattr(type(pilot), "act_batch", None)
    every = max(1, int(getattr(pilot, "board_every", 1)))
    queue = iter(enumerate(episodes))
    waiting = True  # False once board has found the grid's episodes all boarded
    flights: list[tuple[int, Flight, list | None] | None] = [None] * n

    def board(slot: int) -> None:
        """The next grid episode takes ``slot`` (one that ends at once lands at once)."""
        nonlocal waiting
        for index, (obstacles, speed, _, seed) in queue:
            frames: list[np.ndarray] | None = [] if keep_frames else None
            sink = (lambda t, rgb, *_: frames.append(rgb)) if keep_frames else None
            flight = Flight(
                envs[slot], pilots[slot], seed, obstacles, speed, frame_sink=sink, image_quality=image_quality
            )
            if not flight.done:
                flights[slot] = (index, flight, frames)
                return
            landed(index, flight.result(), pilots[slot], frames)
        waiting = False  # the slot stays free

    try:
        envs.extend(make_env() for _ in range(n))
        step = 0  # the batch's clock
        while True:
            if step % every == 0:  # free slots board, in slot order: grid order
                for slot in range(n):
                    if flights[slot] is None and waiting:
                        board(slot)
            live = [slot for slot in range(n) if flights[slot] is not None]
            if not live:
                if not waiting:
                    break
                step += every - step % every  # nothing flies before the next boarding
                continue
            views = [flights[slot][1].view() for slot in live]
            if act_batch is not None:
                actions = act_batch([pilots[slot] for slot in live], views)
            else:
                actions = [pilots[slot].act(view) for slot, view in zip(live, views)]
            for slot, action in zip(live, actions):
                flights[slot][1].step(action)
            for slot in live:  # in slot order: the grid order of the episodes that board is fixed
                index, flight, frames = flights[slot]
                if flight.done:
                    landed(index, flight.result(), pilots[slot], frames)
                    flights[slot] = None
            step += 1
    finally:
        for env in envs:
            env.close()
