"""Where the debris is at every control step of an episode, and how far points are from it then.

The dynamic tier's expert scores each rollout step against the obstacles where they will be at
that step (:meth:`Scenario.obstacle_poses`: exact drift and tumble), so the poses are taken once
per episode on the control grid. Distances are those of :func:`orbitdata.scenario.geometry.signed_distance`
(exact; a lower bound for ellipsoids), batched over points, steps and obstacles.
"""

from __future__ import annotations

import numpy as np

from orbitdata.scenario.spec import Scenario
from orbitdata.schema import DT


def _rotations(quats: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) -> (..., 3, 3) rotations (local -> world)."""
    w, x, y, z = np.moveaxis(quats, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _signed_distance(shape: str, size, q: np.ndarray) -> np.ndarray:
    """Distances (...) from points ``q`` (..., 3) in an obstacle's own frame to its surface."""
    a, b, c = size
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    if shape == "sphere":
        return np.sqrt(x * x + y * y + z * z) - a
    if shape == "box":
        d = np.abs(q) - np.array([a, b, c])
        return np.linalg.norm(np.maximum(d, 0.0), axis=-1) + np.minimum(d.max(axis=-1), 0.0)
    if shape == "capsule":
        return np.sqrt(x * x + y * y + (z - np.clip(z, -b, b)) ** 2) - a
    if shape == "cylinder":
        dr, dz = np.hypot(x, y) - a, np.abs(z) - b
        return np.minimum(np.maximum(dr, dz), 0.0) + np.hypot(np.maximum(dr, 0.0), np.maximum(dz, 0.0))
    # ellipsoid: a lower bound, as the planner's
    return (np.sqrt((x / a) ** 2 + (y / b) ** 2 + (z / c) ** 2) - 1.0) * min(a, b, c)


class DebrisField:
    """The obstacles' poses at control steps 0 .. ``frames`` - 1 (constant in a static scene)."""

    def __init__(self, scenario: Scenario, frames: int):
        poses = scenario.obstacle_poses(np.arange(frames) * DT)  # (F, N, 7)
        self.centres = poses[..., :3]  # (F, N, 3) m, world
        self.rotations = _rotations(poses[..., 3:])  # (F, N, 3, 3) local -> world
        self.shapes = [(ob.shape, ob.size) for ob in scenario.obstacles]
        self.frames = frames

    def clearance(self, points: np.ndarray, first_frame: int, stride: int = 1) -> np.ndarray:
        """(K, H) signed distance from ``points`` (K, H, 3) (row h at control step ``first_frame + h *
        stride``) to the nearest obstacle surface then; +inf without obstacles. Steps past the last
        pose use it."""
        K, H, _ = points.shape
        if not self.shapes:
            return np.full((K, H), np.inf)
        frames = np.minimum(first_frame + stride * np.arange(H), self.frames - 1)
        relative = points[:, :, None, :] - self.centres[frames][None]  # (K, H, N, 3) world
        local = np.einsum("khnj,hnji->khni", relative, self.rotations[frames])  # R^T (p - c)
        distances = [_signed_distance(shape, size, local[:, :, i]) for i, (shape, size) in enumerate(self.shapes)]
        return np.min(distances, axis=0)
