"""Fly a pilot over an evaluation grid (obstacle count x initial speed) and count outcomes.

This is the paper's closed-loop grid (1/3/5 obstacles x v0 = 1/2 m/s); the learned planner
will be flown on exactly the same seeds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from orbitdata.config import GenerationConfig
from orbitdata.pilots import PILOTS, make_pilot
from orbitdata.rollout import fly_episode
from orbitdata.schema import FPS, OUTCOMES
from orbitdata.seeding import grid_seed
from orbitdata.sim.env import CubeSatEnv
from orbitdata.viz.topdown import TopDownMap
from orbitdata.viz.video import write_video


@dataclass
class CellResult:
    obstacles: int
    speed: float
    episodes: int
    success: int = 0
    collision: int = 0
    timeout: int = 0
    out_of_fuel: int = 0

    def add(self, outcome: str) -> None:
        setattr(self, outcome, getattr(self, outcome) + 1)

    @property
    def success_rate(self) -> float:
        return self.success / self.episodes if self.episodes else 0.0


def check_grid(pilot: str, obstacles: list[int], speeds: list[float], episodes: int) -> None:
    if pilot not in PILOTS:
        raise ValueError(f"unknown pilot {pilot!r}; expected one of {', '.join(PILOTS)}")
    if not obstacles or not speeds:
        raise ValueError("the grid is empty: give at least one obstacle count and one speed")
    if any(n < 0 for n in obstacles):
        raise ValueError(f"obstacle counts must be >= 0, got {obstacles}")
    if any(not np.isfinite(v) or v < 0 for v in speeds):
        raise ValueError(f"speeds must be finite and >= 0 m/s, got {speeds}")
    if episodes < 1:
        raise ValueError(f"episodes per setting must be >= 1, got {episodes}")


def _video_frame(obs_rgb: np.ndarray, view: TopDownMap, base: np.ndarray, positions, hit) -> np.ndarray:
    side = obs_rgb.shape[0]
    top = view.draw_path(base.copy(), np.array(positions), hit)
    top = cv2.resize(top, (side, side), interpolation=cv2.INTER_AREA)
    return np.concatenate([obs_rgb, top], axis=1)


def fly_grid(
    pilot: str,
    obstacles: list[int],
    speeds: list[float],
    episodes: int,
    seed: int = 0,
    config: GenerationConfig = GenerationConfig(),
    video_dir: Path | None = None,
    video_format: str = ".mp4",
    on_episode: Callable[[CellResult, str], None] | None = None,
) -> list[CellResult]:
    """Fly ``episodes`` seeded episodes per (obstacles, speed) cell; render only for videos."""
    check_grid(pilot, obstacles, speeds, episodes)
    sim = dataclasses.replace(config.sim, render=video_dir is not None)
    env = CubeSatEnv(sim, config.scenario)
    cells = []
    try:
        for n in obstacles:
            for v in speeds:
                cell = CellResult(obstacles=n, speed=float(v), episodes=episodes)
                for k in range(episodes):
                    s = grid_seed(seed, n, v, k)
                    frames: list = []
                    sink = (lambda t, rgb, *_: frames.append(rgb)) if video_dir is not None else None
                    result = fly_episode(env, make_pilot(pilot, config.pilots, sim.cubesat), s, n, v, frame_sink=sink)
                    cell.add(result.outcome)
                    if video_dir is not None:
                        positions = result.states[:, 0:3]
                        view = TopDownMap(result.scenario, frames[0].shape[0] * 2, positions)
                        base = view.background()
                        hit = positions[-1] if result.outcome == "collision" else None
                        video = [
                            _video_frame(f, view, base, positions[: t + 1], hit if t == len(frames) - 1 else None)
                            for t, f in enumerate(frames)
                        ]
                        name = f"{pilot}-obst{n}-v{v:g}-ep{k:03d}-{result.outcome}{video_format}"
                        write_video(Path(video_dir) / name, video, FPS)
                    if on_episode:
                        on_episode(cell, result.outcome)
                cells.append(cell)
    finally:
        env.close()
    return cells


def grid_report(pilot: str, seed: int, cells: list[CellResult]) -> dict:
    return {
        "pilot": pilot,
        "seed": seed,
        "settings": [
            {"obstacles": c.obstacles, "speed": c.speed, "episodes": c.episodes,
             **{o: getattr(c, o) for o in OUTCOMES}}
            for c in cells
        ],
    }
