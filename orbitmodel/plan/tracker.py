"""A non-learned tracker of moving obstacles in the depth point memory (issue 40's way (b)).

Each frame's world-frame points (``obstacles.depth_to_points``) are clustered into obstacles:
the connected components of points closer than ``link`` plus their two cell radii (the spheres of
a surface's neighbouring cells touch, so one surface is one component at any range). A cluster
continues the track whose points, carried along the track's velocity to this frame's time, come
nearest to it, their spheres within ``gate`` metres (nearest pairs first, one cluster per
track); a cluster that continues none starts a track. A track's velocity is the least-squares
slope of its clusters' centroids against time over its last ``window`` frames, shrunk towards
zero by the slope's standard error (``confidence``), capped at ``speed_cap``, and zero until
``min_frames`` of those frames fed the fit.

A depth map sees only the near face of an object, so the centroid of what is seen moves when the
view changes, and most when the image's border cuts the object: a cluster with a point on the
border keeps its points but is left out of the velocity fit. The planner plans around each
track's points of its last ``point_frames`` frames, each carried along the track's velocity to the
queried time (:class:`MovingCloud`); a track unseen for ``forget`` frames is dropped. With every
velocity zero this is the static planner's point memory, kept per obstacle.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import torch

from orbitmodel.plan.obstacles import PointCloud


@dataclass(frozen=True)
class TrackerConfig:
    """The tracker's knobs: ``point_frames``, ``link`` and ``confidence`` chosen on the dynamic tier's
    validation episodes (``benchmarks/check_tracker.py``, docs/results.md), the others a reasoned start.

    Args:
        window: frames of a track whose centroids the velocity is fitted to (25 = 1 s: the 16x16
            map's coarse cells make each centroid noisy, and debris drifts at a near-constant
            velocity, so a long fit loses little).
        point_frames: frames of a track whose points it plans around (its newest; more fill the
            holes of one view, and each older one carries the velocity's error further).
        link: metres beyond the two points' cell radii within which they are one obstacle (wide
            enough to join the cells of a steep surface, such as a sphere's limb, to its face).
        gate: metres: the widest gap between a cluster's spheres and a track's carried ones for
            the cluster to continue the track.
        min_frames: frames off the image border a track needs in its window before it moves
            (fewer: velocity zero, the tracker does not invent motion from a glimpse).
        speed_cap: m/s, the fastest a track may move (the dynamic tier draws debris up to 1 m/s).
        forget: frames a track is kept, carried along its velocity, after it was last seen.
        confidence: the fitted slope v is shrunk to ``v max(0, 1 - confidence^2 se^2 / |v|^2)``,
            se^2 the variance of the slope's estimate from the fit's residuals (0: no shrinkage;
            a coarse map's centroids wander, and a slope no larger than its noise is dropped).
    """

    window: int = 25
    point_frames: int = 25
    link: float = 0.25
    gate: float = 0.5
    min_frames: int = 8
    speed_cap: float = 1.5
    forget: int = 50
    confidence: float = 3.0

    def __post_init__(self):
        if not 2 <= self.min_frames <= self.window or not 1 <= self.point_frames <= self.window:
            raise ValueError(
                f"min_frames={self.min_frames} must be in 2..window={self.window} and "
                f"point_frames={self.point_frames} in 1..window"
            )
        if self.link < 0 or self.gate <= 0 or self.speed_cap < 0 or self.forget < 1 or self.confidence < 0:
            raise ValueError(
                f"link={self.link} must be >= 0, gate={self.gate} > 0, speed_cap={self.speed_cap} >= 0, "
                f"forget={self.forget} >= 1 and confidence={self.confidence} >= 0"
            )


def clusters(points: np.ndarray, radii: np.ndarray, link: float) -> np.ndarray:
    """(N,) labels 0..C-1 of the connected components of ``points`` (N, 3) metres, two points
    joined when they are at most ``link`` + their two ``radii`` (N,) apart."""
    from scipy.sparse.csgraph import connected_components

    if len(points) == 0:
        return np.zeros(0, int)
    gap = np.linalg.norm(points[:, None] - points[None], axis=-1) - radii[:, None] - radii[None]  # (N, N)
    return connected_components(gap <= link, directed=False)[1]


def fit_velocity(times: np.ndarray, centroids: np.ndarray, confidence: float = 0.0) -> np.ndarray:
    """(3,) m/s: the least-squares slope of ``centroids`` (F, 3) metres against ``times`` (F,) s,
    shrunk towards zero by ``confidence`` standard errors (:class:`TrackerConfig`)."""
    dt = times - times.mean()
    spread = (dt**2).sum()
    if spread <= 0:
        return np.zeros(3)
    centred = centroids - centroids.mean(0)  # (F, 3)
    slope = (dt[:, None] * centred).sum(0) / spread
    if confidence > 0:
        residual = centred - dt[:, None] * slope  # (F, 3)
        variance = (residual**2).sum() / max(len(times) - 2, 1) / spread  # of the slope, summed over axes
        slope = slope * max(0.0, 1.0 - confidence**2 * variance / max(float(slope @ slope), 1e-12))
    return slope


@dataclass
class Frame:
    """One frame's cluster of a track."""

    time: float  # s
    points: np.ndarray  # (n, 3) metres, world
    radii: np.ndarray  # (n,) metres
    clipped: bool  # cut by the image border: its centroid is left out of the velocity fit

    @property
    def centroid(self) -> np.ndarray:
        return self.points.mean(0)


@dataclass
class Track:
    """One obstacle followed across frames."""

    frames: deque  # of Frame, the last ``window``
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m/s, world
    unseen: int = 0  # frames since it was last seen

    def carried(self, time: float, frames: int) -> tuple[np.ndarray, np.ndarray]:
        """The points (n, 3) of its newest ``frames`` frames moved along its velocity to ``time`` s,
        and their radii (n,)."""
        newest = list(self.frames)[-frames:]
        points = [f.points + self.velocity * (time - f.time) for f in newest]
        return np.concatenate(points), np.concatenate([f.radii for f in newest])

    def refit(self, config: TrackerConfig) -> None:
        fed = [f for f in self.frames if not f.clipped]
        if len(fed) < config.min_frames:
            self.velocity = np.zeros(3)
            return
        v = fit_velocity(np.array([f.time for f in fed]), np.stack([f.centroid for f in fed]), config.confidence)
        speed = float(np.linalg.norm(v))
        self.velocity = v * (config.speed_cap / speed) if speed > config.speed_cap else v


class Tracker:
    """The tracks of one episode, fed one frame's points at a time (:meth:`add`)."""

    def __init__(self, config: TrackerConfig = TrackerConfig()):
        self.config = config
        self.tracks: list[Track] = []

    def reset(self) -> None:
        self.tracks = []

    def add(self, points: np.ndarray, radii: np.ndarray, time: float, edge: np.ndarray | None = None) -> None:
        """Fold in a frame: ``points`` (N, 3) metres, world, ``radii`` (N,) metres, seen at ``time`` s;
        ``edge`` (N,) bool: the points of cells on the image's border (None: none are)."""
        c = self.config
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        radii = np.asarray(radii, dtype=np.float64).reshape(-1)
        edge = np.zeros(len(points), bool) if edge is None else np.asarray(edge, bool)
        labels = clusters(points, radii, c.link)
        count = int(labels.max()) + 1 if len(labels) else 0
        pairs = []  # (distance, cluster, track) within the gate
        for j, track in enumerate(self.tracks):
            near = _gaps(*track.carried(time, c.point_frames), points, radii)  # (N,) metres
            distance = np.full(count, math.inf)
            np.minimum.at(distance, labels, near)
            pairs += [(float(d), i, j) for i, d in enumerate(distance) if d <= c.gate]
        matched: dict[int, Track] = {}  # cluster -> the track it continues
        for _, i, j in sorted(pairs):
            if i not in matched and all(t is not self.tracks[j] for t in matched.values()):
                matched[i] = self.tracks[j]
        continued = {id(t) for t in matched.values()}
        for track in self.tracks:
            track.unseen = 0 if id(track) in continued else track.unseen + 1
        self.tracks = [t for t in self.tracks if t.unseen < c.forget]
        for i in range(count):
            mine = labels == i
            track = matched.get(i)
            if track is None:
                track = Track(deque(maxlen=c.window))
                self.tracks.append(track)
            track.frames.append(Frame(time, points[mine], radii[mine], bool(edge[mine].any())))
            track.refit(c)

    def field(self, time: float, reach: float = 2.0) -> "MovingCloud":
        """What to plan around from ``time`` s: each track's points carried along its velocity."""
        frames = self.config.point_frames
        return MovingCloud([(*t.carried(time, frames), t.velocity) for t in self.tracks], time, reach)


def _gaps(reference: np.ndarray, reference_radii: np.ndarray, points: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(N,) metres between the sphere of each of ``points`` (N, 3), ``radii`` (N,) and the sphere of
    the nearest centre of ``reference`` (M, 3), ``reference_radii`` (M,)."""
    from scipy.spatial import cKDTree

    if len(points) == 0 or len(reference) == 0:
        return np.full(len(points), math.inf)
    distance, index = cKDTree(reference).query(points)
    return distance - radii - reference_radii[index]


class MovingCloud:
    """Obstacles as clouds of spheres, each cloud moving at its own constant velocity.

    ``clouds``: (points (n, 3) metres at ``time`` s, radii (n,), velocity (3,) m/s) per obstacle.
    A position at time t is tested against each cloud where it is then, that is the position
    moved back by velocity x (t - ``time``) against the cloud as it stands now.
    """

    def __init__(self, clouds: list[tuple[np.ndarray, np.ndarray, np.ndarray]], time: float, reach: float = 2.0):
        self.time = float(time)
        self.clouds = [(PointCloud(p, r, reach), torch.tensor(v, dtype=torch.float32)) for p, r, v in clouds]
        self.points = np.concatenate([c.points for c, _ in self.clouds]) if self.clouds else np.zeros((0, 3))
        self.velocities = np.array([v.numpy() for _, v in self.clouds]).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self.points)

    def clearance(self, positions: torch.Tensor, times: torch.Tensor | None = None) -> torch.Tensor:
        """(..., H, 3) metres, row h at ``times[h]`` (H,) s -> (..., H) metres to the nearest sphere
        surface then (+inf beyond reach; NaN where a position is not finite, as
        :meth:`PointCloud.clearance`; +inf everywhere for a field without points). Without
        times: (..., 3) -> (...,) at this field's time.

        A cloud is not queried when its :attr:`PointCloud.box` lies, along some axis, beyond the
        box of all the positions widened by how far its velocity carries them: it would answer
        +inf for every one of them."""
        out = torch.full(positions.shape[:-1], math.inf)
        if not len(self):
            return out
        ahead = None if times is None else (torch.as_tensor(times, dtype=torch.float64) - self.time).float()[:, None]
        finite = torch.isfinite(positions).all(-1)  # (..., H)
        finite_positions = positions.detach()[finite].double()  # (M, 3)
        if len(finite_positions):
            lo, hi = finite_positions.amin(0).numpy(), finite_positions.amax(0).numpy()
            furthest = 0.0 if ahead is None else float(ahead.abs().max())  # s
            largest = float(np.maximum(np.abs(lo), np.abs(hi)).max())  # metres
        for cloud, velocity in self.clouds:
            moving = ahead is not None and bool(velocity.any())
            if len(finite_positions):
                # every moved position lies within the positions' box, widened by how far the velocity
                # carries them, and by more than the float32 rounding of the move (two roundings of
                # at most 2^-24 of the largest coordinate each)
                carry = furthest * velocity.abs().double().numpy()
                shift = carry + 1e-6 * (largest + carry.max()) + 1e-3 if moving else 0.0
                box_lo, box_hi = cloud.box
                if (box_hi < lo - shift).any() or (box_lo > hi + shift).any():
                    continue
            moved = positions - ahead * velocity if moving else positions
            out = torch.minimum(out, cloud.clearance(moved))
        return torch.where(finite, out, torch.nan)
