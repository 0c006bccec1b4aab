"""Fly a pilot over an evaluation grid (obstacle count x initial speed) and count outcomes.

This is the paper's closed-loop grid (1/3/5 obstacles x v0 = 1/2 m/s): the seeds are a pure
function of (root seed, cell, episode), so a learned pilot is flown on exactly the same
episodes as the expert. One pilot (made once by its factory) flies every episode.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from orbitdata.fly.config import FlightConfig
from orbitdata.fly.pilot import Pilot
from orbitdata.fly.record import episode_summary
from orbitdata.fly.registry import PilotFactory, make_pilot
from orbitdata.fly.rollout import EpisodeResult, FrameSink, fly_episode
from orbitdata.scenario.config import DYNAMIC, MAX_OBSTACLES, STATIC
from orbitdata.schema import outcomes
from orbitdata.seeding import grid_seed
from orbitdata.sim.env import CubeSatEnv


@dataclass
class CellResult:
    obstacles: int
    speed: float  # m/s, initial
    episodes: int
    success: int = 0
    collision: int = 0
    timeout: int = 0
    out_of_fuel: int = 0
    tumbling: int = 0  # the dynamic tier's outcome only (schema.outcomes)
    # The dynamic tier's sampling: debris pieces its episodes hold, and draws rejected as
    # unsurvivable on the way to them (``Dynamics.unsurvivable_draws``); 0 on the static tier.
    debris: int = 0
    unsurvivable_draws: int = 0
    # one ``record.episode_summary`` per episode flown, with its setting, number and seed
    records: list[dict] = field(default_factory=list)

    def add(self, outcome: str) -> None:
        setattr(self, outcome, getattr(self, outcome) + 1)

    def count(self, record: dict) -> None:
        """Count one flown episode from its record (``record.episode_summary``): its outcome and, on
        the dynamic tier, its debris and the draws rejected on the way to them."""
        self.add(record["outcome"])
        self.debris += record.get("debris", 0)
        self.unsurvivable_draws += record.get("unsurvivable_draws", 0)

    @property
    def success_rate(self) -> float:
        return self.success / self.episodes if self.episodes else 0.0


# Called after each episode with its cell (counts so far), its number in the cell and its record.
EpisodeHook = Callable[[CellResult, int, EpisodeResult], None]


def check_grid(obstacles: list[int], speeds: list[float], episodes: int) -> None:
    if not obstacles or not speeds:
        raise ValueError("the grid is empty: give at least one obstacle count and one speed")
    if any(not 0 <= n <= MAX_OBSTACLES for n in obstacles):
        raise ValueError(f"obstacle counts must be 0 to {MAX_OBSTACLES}, got {obstacles}")
    if any(not np.isfinite(v) or v < 0 for v in speeds):
        raise ValueError(f"speeds must be finite and >= 0 m/s, got {speeds}")
    if episodes < 1:
        raise ValueError(f"episodes per setting must be >= 1, got {episodes}")


def fly_grid(
    pilot: str | PilotFactory,
    obstacles: list[int],
    speeds: list[float],
    episodes: int,
    seed: int = 0,
    config: FlightConfig = FlightConfig(),
    render: bool | None = None,
    frame_sink: FrameSink | None = None,
    on_episode: EpisodeHook | None = None,
    image_quality: int | None = None,
    thrust_noise: float = 0.0,
    noise_hold: int = 1,
    **options,
) -> list[CellResult]:
    """Fly ``episodes`` seeded episodes per (obstacles, speed) cell.

    Args:
        pilot: a registered pilot name, or a factory ``factory(config, **options) -> Pilot``.
        config: the simulator, scenario and built-in pilots' settings (``GenerationConfig.flight``).
        render: render the camera (``obs["image"]``; ``obs["depth"]`` and ``obs["depth_low"]`` for a
            pilot that ``sees_depth``);
            ``None``: when the pilot needs images or ``frame_sink`` wants frames.
        frame_sink: called with every rendered frame (``t`` restarts at 0 each episode).
        on_episode: called after every episode (progress bars, videos).
        image_quality: hand the pilot its camera through the dataset's JPEG codec at this quality
            (a dataset's ``DatasetConfig.jpeg_quality``), as the dataset stores it: what a pilot
            trained on the dataset saw. ``None``: the raw renders.
        thrust_noise, noise_hold: add Gaussian noise of this sigma to every action, redrawn every
            ``noise_hold`` control steps (``orbitdata.fly.noise.ThrustNoise``; 0: none).
        **options: passed to the pilot's factory.
    """
    check_grid(obstacles, speeds, episodes)
    flyer: Pilot = make_pilot(pilot, config, **options) if isinstance(pilot, str) else pilot(config, **options)
    if not isinstance(flyer, Pilot):
        raise TypeError(f"the pilot factory returned {type(flyer).__name__}, not an orbitdata.fly.Pilot")
    if thrust_noise:
        from orbitdata.fly.noise import ThrustNoise

        flyer = ThrustNoise(flyer, thrust_noise, noise_hold)
    if render is None:
        render = flyer.needs_images or frame_sink is not None
    elif not render and (flyer.needs_images or frame_sink is not None):
        raise ValueError(f"pilot {flyer.name!r} needs camera images (or frames were asked for), but render=False")
    sim = dataclasses.replace(config.sim, render=render)
    env = CubeSatEnv(sim, config.scenario)
    cells = []
    try:
        for n in obstacles:
            for v in speeds:
                cell = CellResult(obstacles=n, speed=float(v), episodes=episodes)
                for k in range(episodes):
                    episode_seed = grid_seed(seed, n, v, k)
                    result = fly_episode(
                        env, flyer, episode_seed, n, v, frame_sink=frame_sink, image_quality=image_quality
                    )
                    record = {
                        "obstacles": n,
                        "speed": float(v),
                        "episode": k,
                        "seed": episode_seed,
                        **episode_summary(result, sim.cubesat),
                    }
                    cell.count(record)
                    cell.records.append(record)
                    if on_episode:
                        on_episode(cell, k, result)
                cells.append(cell)
    finally:
        env.close()
    return cells


def pooled(cells: list[CellResult]) -> tuple[int, int]:
    """(successes, episodes) over the whole grid."""
    return sum(c.success for c in cells), sum(c.episodes for c in cells)


def grid_report(pilot: str, seed: int, cells: list[CellResult], flight: dict | None = None, tier: str = STATIC) -> dict:
    """The ``--json`` table: the pilot, the grid seed, the outcome counts per setting, (``flight``)
    how it flew (pilot options, codec, thrust noise) and each episode's record
    (``record.episode_summary``, where the cells kept them). A grid of another tier than the static one
    names it (``tier``) and, for the dynamic tier, counts the debris draws rejected as unsurvivable
    against the pieces kept (``rejections``: the tier's rejection rate is rejected / (rejected + kept))."""
    extra = {}
    if tier != STATIC:
        extra["tier"] = tier
    if tier == DYNAMIC:
        rejected = sum(c.unsurvivable_draws for c in cells)
        kept = sum(c.debris for c in cells)
        extra["rejections"] = {
            "unsurvivable_draws": rejected,
            "debris": kept,
            "rate": rejected / (rejected + kept) if rejected + kept else 0.0,
        }
    return {
        "pilot": pilot,
        "seed": seed,
        **extra,
        **({"flight": flight} if flight is not None else {}),
        "settings": [
            {
                "obstacles": c.obstacles,
                "speed": c.speed,
                "episodes": c.episodes,
                **{o: getattr(c, o) for o in outcomes(tier)},
            }
            for c in cells
        ],
        **({"episodes": [r for c in cells for r in c.records]} if any(c.records for c in cells) else {}),
    }
