"""Videos of ``orbitdata fly``: each episode's onboard camera beside a top-down map of its path
(on the dynamic tier also each piece of debris' track, where it is now and where the fault began).

:class:`FlightVideos` plugs into :func:`orbitdata.fly.grid.fly_grid`: ``frame`` is its frame
sink (it keeps the current episode's camera frames) and ``episode`` its per-episode hook (it
draws the map under each frame and streams the video to disk).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from orbitdata.fly.rollout import EpisodeResult
from orbitdata.schema import DT, FPS
from orbitdata.state import POSITION
from orbitdata.viz.topdown import PlaneMap
from orbitdata.viz.video import check_video_format, write_video


def flight_frames(camera: list[np.ndarray], result: EpisodeResult):
    """(H, 2H, 3) uint8 frames: camera frame t beside the top-down map of the path up to t."""
    side = camera[0].shape[0]
    positions = result.states[:, POSITION]
    dynamics = result.scenario.dynamics
    poses = None if dynamics is None else result.scenario.obstacle_poses(np.arange(len(positions)) * DT)  # (L, N, 7)
    points = positions if poses is None else np.concatenate([positions, poses[:, :, :3].reshape(-1, 3)])
    view = PlaneMap(result.scenario, side * 2, points)
    base = view.background() if poses is None else view.draw_tracks(view.background(), poses)
    onset = None if dynamics is None or not dynamics.fault.active(len(positions) - 1) else dynamics.fault.onset_step
    hit = positions[-1] if result.outcome == "collision" else None
    for t, rgb in enumerate(camera):
        top = base.copy()
        if poses is not None:
            view.draw_debris(top, poses[t])
        top = view.draw_path(top, positions[: t + 1], hit if t == len(camera) - 1 else None)
        if onset is not None and t >= onset:
            view.draw_fault(top, positions[onset])
        top = cv2.resize(top, (side, side), interpolation=cv2.INTER_AREA)
        yield np.concatenate([rgb, top], axis=1)


class FlightVideos:
    """Writes ``{pilot}-obst{n}-v{v}-ep{k:03d}-{outcome}{suffix}`` into ``folder`` for every episode."""

    def __init__(self, folder: Path, suffix: str = ".mp4", fps: float = FPS):
        self.folder, self.fps = Path(folder), fps
        self.suffix = check_video_format(Path(f"video{suffix}"))
        self._camera: list[np.ndarray] = []
        self.written: list[Path] = []

    def frame(self, t: int, rgb: np.ndarray, depth: np.ndarray, depth_low: np.ndarray) -> None:
        if t == 0:
            self._camera = []
        self._camera.append(rgb)

    def episode(self, cell, k: int, result: EpisodeResult) -> None:
        name = f"{result.pilot}-obst{cell.obstacles}-v{cell.speed:g}-ep{k:03d}-{result.outcome}{self.suffix}"
        self.written.append(write_video(self.folder / name, flight_frames(self._camera, result), self.fps))
        self._camera = []
