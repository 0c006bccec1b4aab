"""Episode videos of a planning pilot: the camera beside a top-down map that also draws what the
planner believed at each step (its cheapest imagined path and the obstacle points it used)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from orbitdata.schema import FPS
from orbitdata.viz.topdown import PlaneMap
from orbitdata.viz.video import write_video
from orbitmodel.kinematics import P

IMAGINED = (255, 210, 60)  # RGB: the imagined path
BELIEVED = (230, 80, 230)  # RGB: the obstacle points


def draw_belief(img: np.ndarray, view: PlaneMap, path: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Draw the believed points (N, 3) and the imagined path (H, 3), world metres, in place."""
    for u, v in view.polyline(points) if len(points) else ():
        cv2.circle(img, (int(u), int(v)), 2, BELIEVED, -1, cv2.LINE_AA)
    if len(path) > 1:
        cv2.polylines(img, [view.polyline(path)], False, IMAGINED, 1, cv2.LINE_AA)
    return img


def episode_frames(frames: list[np.ndarray], result, replans: list, side: int = 256) -> list[np.ndarray]:
    """One (side, 2 side, 3) RGB frame per camera frame: camera | map with path and belief."""
    positions = result.states[:, P]
    view = PlaneMap(result.scenario, side, positions)
    base = view.background()
    by_step = sorted(replans, key=lambda r: r.step)
    out, j = [], -1
    for t, rgb in enumerate(frames):
        while j + 1 < len(by_step) and by_step[j + 1].step <= t:
            j += 1
        top = base.copy()
        if j >= 0 and t < len(frames) - 1:
            draw_belief(top, view, by_step[j].path, by_step[j].points)
        hit = positions[t] if (result.outcome == "collision" and t == len(frames) - 1) else None
        view.draw_path(top, positions[: t + 1], hit)
        camera = cv2.resize(rgb, (side, side), interpolation=cv2.INTER_NEAREST)
        out.append(np.concatenate([camera, top], axis=1))
    return out


def write_episode_video(path: Path, frames: list[np.ndarray], result, replans: list) -> Path:
    return write_video(path, episode_frames(frames, result, replans), FPS)
