"""What the planner believes is in the way: clearance from a point to the nearest obstacle.

Each source answers ``clearance(positions (..., H, 3), times (H,) | None) -> (..., H)`` metres
(negative inside, +inf when nothing is near), row h of the positions at ``times[h]`` seconds
into the episode; a field of obstacles that do not move ignores the times:

* :class:`PointCloud`: the 16x16 depth map of the current frame (the depth head's prediction,
  or the rendered ``depth_low``) back-projected through the camera into the world frame with the
  current state, each point a sphere as wide as its cell (what a learned pilot knows);
* :class:`TrueObstacles`: the scenario's obstacles, exact signed distances (oracles only): on the
  dynamic tier where each will be at each time ("true"), or held where they are now ("frozen").
The tracker's moving clouds (``plan.tracker``) answer the same call.

Camera facts (``orbitdata.sim``): the camera sits on the body's +x face looking along body +x,
image up = body +z; ``depth_low`` is the 4x4 (at 64 px) area mean of the *z-depth* along the
optical axis, no-return pixels counted at the far plane (``orbitdata.sim.render.pool_depth``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import torch

from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.schema import DEPTH_LOW_SIDE
from orbitdata.sim.config import SimConfig
from orbitmodel.kinematics import ROT, P, rot6d_to_matrix


@dataclass(frozen=True)
class Camera:
    """Pinhole model of the onboard camera, in the body frame.

    Attributes:
        fovy_deg: vertical (= horizontal, square image) field of view.
        far: metres; depth at or beyond it means no return.
        position: (3,) metres, the optical centre in the body frame.
        rotation: (3, 3) camera -> body (columns: camera x right, y up, z backwards, MuJoCo's).
    """

    fovy_deg: float
    far: float
    position: tuple[float, float, float]
    rotation: tuple[tuple[float, ...], ...]

    @classmethod
    def from_sim(cls, sim: SimConfig = SimConfig(), fovy_deg: float | None = None) -> "Camera":
        """Read the pose from the simulator's own MJCF, so it cannot drift from the renderer."""
        import mujoco

        from orbitdata.sim.mjcf import CAMERA, build_mjcf

        model = mujoco.MjModel.from_xml_string(build_mjcf(Scenario(obstacles=(), goal=(1.0, 0.0, 0.0)), sim))
        cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA)
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, model.cam_quat[cam])
        return cls(
            fovy_deg=float(sim.camera.fovy_deg if fovy_deg is None else fovy_deg),
            far=float(sim.camera.far),
            position=tuple(float(x) for x in model.cam_pos[cam]),
            rotation=tuple(tuple(float(x) for x in row) for row in R.reshape(3, 3)),
        )

    def cell_rays(self, side: int = DEPTH_LOW_SIDE) -> np.ndarray:
        """(side, side, 3) body-frame vectors through the cell centres, scaled to unit z-depth.

        Row 0 is the top of the image (camera +y), column 0 its left (camera -x).
        """
        half = math.tan(math.radians(self.fovy_deg) / 2)  # image half-width at unit depth
        centres = ((np.arange(side) + 0.5) / side * 2 - 1) * half  # (side,) left/top -> right/bottom
        x, y = np.meshgrid(centres, -centres)  # x right, y up
        ray_cam = np.stack([x, y, -np.ones_like(x)], -1)  # looking along -z (MuJoCo)
        return ray_cam @ np.asarray(self.rotation).T

    def cell_width(self, side: int = DEPTH_LOW_SIDE) -> float:
        """Width of one cell at unit depth (metres per metre)."""
        return 2 * math.tan(math.radians(self.fovy_deg) / 2) / side


def supported_cells(depth: np.ndarray, near: np.ndarray, support: int, tolerance: float = 0.3) -> np.ndarray:
    """(16, 16) bool: the ``near`` cells with at least ``support`` of their 8 neighbours also
    ``near`` and at a depth within ``tolerance`` (a fraction of the cell's own depth) of theirs.

    A surface covers neighbouring cells at similar depths; a lone cell is more likely a stray
    prediction of the depth head (a "phantom" in the sky, or a smear behind a near obstacle).
    The tolerance is relative to each cell's own depth, so it is one-sided: of two lone
    neighbours at 2.0 and 2.8 m, the farther one is kept and the nearer one is not (0.8 m is
    within 30 % of 2.8 m, not of 2.0 m). Border cells have fewer neighbours (5, corners 3), so a
    ``support`` above 3 drops the image's corners and above 5 its whole border.
    """
    d = np.where(near, depth, np.nan)
    padded = np.pad(d, 1, constant_values=np.nan)
    count = np.zeros(depth.shape, int)
    rows, cols = depth.shape
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                other = padded[1 + dy : 1 + dy + rows, 1 + dx : 1 + dx + cols]
                count += np.abs(other - d) <= tolerance * d  # NaN compares False
    return near & (count >= support)


def kept_cells(depth: np.ndarray, camera: Camera, max_range: float = 20.0, support: int = 0) -> np.ndarray:
    """(16, 16) bool: the cells of a z-depth map (metres) that :func:`depth_to_points` turns into points."""
    depth = np.asarray(depth, dtype=np.float64)
    keep = np.isfinite(depth) & (depth > 0) & (depth < min(max_range, 0.99 * camera.far))
    return supported_cells(depth, keep, support) if support else keep


def border_points(depth: np.ndarray, camera: Camera, max_range: float = 20.0, support: int = 0) -> np.ndarray:
    """(N,) bool, one per point of :func:`depth_to_points` (same order): whether its cell lies on
    the image's border, where the view may cut an object short."""
    side = np.asarray(depth).shape[0]
    border = np.ones((side, side), bool)
    border[1:-1, 1:-1] = False
    return border[kept_cells(depth, camera, max_range, support)]


def depth_to_points(
    depth: np.ndarray,
    state: np.ndarray,
    camera: Camera,
    max_range: float = 20.0,
    footprint: float = 1.0,
    support: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Back-project a (16, 16) z-depth map (metres) seen from ``state`` into world points.

    Cells at or beyond ``min(max_range, 0.99 far)`` (no return, or too far to matter) and
    non-finite cells are dropped, and with ``support`` > 0 the cells without that many
    neighbours at a similar depth (:func:`supported_cells`). Returns points (N, 3) metres, world
    frame relative to the start, and radii (N,) metres: ``footprint`` x half the cell's width at
    its depth, so the spheres of neighbouring cells touch and a seen surface has no holes.
    """
    depth = np.asarray(depth, dtype=np.float64)
    keep = kept_cells(depth, camera, max_range, support)
    d = depth[keep]  # (N,)
    body = np.asarray(camera.position) + d[:, None] * camera.cell_rays(depth.shape[0])[keep]  # (N, 3)
    s = np.asarray(state, dtype=np.float64)
    R = rot6d_to_matrix(torch.as_tensor(s[ROT])).numpy()  # body -> world
    points = s[P] + body @ R.T
    return points, footprint * 0.5 * camera.cell_width(depth.shape[0]) * d


class PointCloud:
    """Obstacles as a union of spheres; nearest-neighbour queries through a k-d tree.

    ``reach``: clearances beyond it are reported as +inf (the cost ignores them anyway), which
    lets the tree prune almost every query far from the points; :attr:`box` (lo (3,), hi (3,))
    metres bounds where an answer can be finite.
    """

    def __init__(self, points: np.ndarray, radii: np.ndarray, reach: float = 2.0, neighbours: int = 4):
        from scipy.spatial import cKDTree

        self.points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.radii = np.asarray(radii, dtype=np.float64).reshape(-1)
        self.reach = float(reach)
        self.k = min(neighbours, len(self.points))
        self._tree = cKDTree(self.points) if len(self.points) else None
        self._pad_radii = np.append(self.radii, 0.0)  # the tree's "no neighbour" index is N
        # The box around the centres widened by the query bound, and a hair more so that rounding
        # never drops a query the tree would answer: outside it no centre lies within the bound,
        # the answer is +inf, and the query is skipped. Empty: a box that holds nothing.
        if len(self.points):
            self._bound = self.reach + float(self.radii.max())
            slack = self._bound * (1 + 1e-9) + 1e-9
            self.box = (self.points.min(0) - slack, self.points.max(0) + slack)
        else:
            self._bound, self.box = 0.0, (np.full(3, np.inf), np.full(3, -np.inf))

    def __len__(self) -> int:
        return len(self.points)

    def clearance(self, positions: torch.Tensor, times: torch.Tensor | None = None) -> torch.Tensor:
        """(..., 3) metres -> (...,) distance to the nearest sphere surface (+inf beyond reach).
        The points stand still: ``times`` is not read. A position that is not finite (a candidate
        whose rollout diverged) gets NaN, so its cost is not finite and MPPI gives it no weight."""
        shape = positions.shape[:-1]
        if self._tree is None:
            return torch.full(shape, math.inf)
        x = positions.detach().reshape(-1, 3).double().numpy()
        finite = np.isfinite(x).all(1)
        gap = np.where(finite, np.inf, np.nan)
        lo, hi = self.box
        ask = np.flatnonzero(finite & ((x >= lo) & (x <= hi)).all(1))  # the rest are beyond the bound
        if len(ask):
            dist, idx = self._tree.query(x[ask], k=self.k, distance_upper_bound=self._bound)  # (M, k) or (M,)
            near = np.asarray(dist) - self._pad_radii[np.asarray(idx)]  # inf where none within bound
            gap[ask] = near.min(-1) if near.ndim == 2 else near
        return torch.from_numpy(gap).float().reshape(shape)


class PointMemory:
    """The points of the last ``frames`` frames, in the world frame (1 = the current frame only)."""

    def __init__(self, frames: int = 1):
        if frames < 1:
            raise ValueError(f"memory of {frames} frames: keep at least the current one")
        self._frames: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=frames)

    def reset(self) -> None:
        self._frames.clear()

    def add(self, points: np.ndarray, radii: np.ndarray) -> None:
        self._frames.append((points, radii))

    def cloud(self, reach: float = 2.0) -> PointCloud:
        if not self._frames:
            return PointCloud(np.zeros((0, 3)), np.zeros(0), reach)
        return PointCloud(
            np.concatenate([p for p, _ in self._frames]), np.concatenate([r for _, r in self._frames]), reach
        )


def _quat_matrix(quat) -> torch.Tensor:
    from orbitdata.state import quat_to_matrix

    return torch.tensor(quat_to_matrix(quat), dtype=torch.float32)


def quat_matrices(quats: np.ndarray) -> torch.Tensor:
    """(..., 4) unit quaternions (w, x, y, z) -> (..., 3, 3) float32 rotations (local -> world),
    ``orbitdata.state.quat_to_matrix`` over many at once."""
    w, x, y, z = np.moveaxis(np.asarray(quats, dtype=np.float64), -1, 0)
    R = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )
    return torch.from_numpy(R).float()


def local_distance(shape: str, size, local: torch.Tensor) -> torch.Tensor:
    """(..., 3) points in an obstacle's own frame -> (...,) metres to its surface, negative inside."""
    lx, ly, lz = local.unbind(-1)
    a, b, c = size
    if shape == "sphere":
        return local.norm(dim=-1) - a
    if shape == "box":
        q = local.abs() - torch.tensor([a, b, c], dtype=torch.float32)
        return q.clamp(min=0).norm(dim=-1) + q.amax(-1).clamp(max=0)
    if shape == "capsule":
        return torch.stack([lx, ly, lz - lz.clamp(-b, b)], -1).norm(dim=-1) - a
    if shape == "cylinder":
        dr, dz = torch.hypot(lx, ly) - a, lz.abs() - b
        return torch.maximum(dr, dz).clamp(max=0) + torch.hypot(dr.clamp(min=0), dz.clamp(min=0))
    k = (local / torch.tensor([a, b, c], dtype=torch.float32)).norm(dim=-1)  # ellipsoid
    return (k - 1) * min(a, b, c)


def signed_distance(ob: Obstacle, x: torch.Tensor) -> torch.Tensor:
    """(..., 3) world points -> (...,) metres to the surface of ``ob``, negative inside.

    The torch twin of ``orbitdata.scenario.geometry.signed_distance`` (same formulas: exact,
    except the ellipsoid's conservative lower bound).
    """
    local = (x - torch.tensor(ob.center, dtype=torch.float32)) @ _quat_matrix(ob.quat)  # R^T (x - c)
    return local_distance(ob.shape, ob.size, local)


MOTIONS = ("true", "frozen")  # how an oracle's true obstacles move in its plans


class TrueObstacles:
    """The scenario's obstacles (privileged: only the oracles get them).

    In a scenario whose debris moves (the dynamic tier), ``motion`` "true" puts each obstacle
    where it will be at each queried time (the exact drift and tumble of
    ``Scenario.obstacle_poses``: the oracles' true debris motion), and "frozen" holds them at
    their pose at ``time`` s (what a planner that believes in a still scene assumes; the pilot
    takes :meth:`now` at each replan). Static obstacles are the same either way.
    """

    def __init__(self, scenario: Scenario, motion: str = "true", time: float = 0.0):
        if motion not in MOTIONS:
            raise ValueError(f"motion={motion!r}: use {' or '.join(MOTIONS)}")
        self.scenario, self.motion, self.time = scenario, motion, float(time)
        self.moving = scenario.dynamics is not None and motion == "true"
        self.obstacles = tuple(scenario.obstacles_at(self.time))

    def now(self, time: float) -> "TrueObstacles":
        """The field to plan with at ``time`` s: this one, or the obstacles frozen where they are then."""
        if self.scenario.dynamics is None or self.motion == "true":
            return self
        return TrueObstacles(self.scenario, self.motion, time)

    def clearance(self, positions: torch.Tensor, times: torch.Tensor | None = None) -> torch.Tensor:
        """(..., H, 3) metres, row h at ``times[h]`` (H,) s -> (..., H) signed distance to the nearest
        obstacle surface then. Without times, or when nothing moves: (..., 3) -> (...,) against the
        obstacles at this field's time."""
        out = torch.full(positions.shape[:-1], math.inf)
        if not self.moving or times is None:
            for ob in self.obstacles:
                out = torch.minimum(out, signed_distance(ob, positions.float()))
            return out
        poses = self.scenario.obstacle_poses(np.asarray(times, dtype=np.float64))  # (H, N, 7)
        centres = torch.from_numpy(poses[..., :3]).float()  # (H, N, 3)
        rotations = quat_matrices(poses[..., 3:])  # (H, N, 3, 3) local -> world
        x = positions.float()
        for i, ob in enumerate(self.scenario.obstacles):
            local = torch.einsum("...hj,hji->...hi", x - centres[:, i], rotations[:, i])  # R^T (x - c)
            out = torch.minimum(out, local_distance(ob.shape, ob.size, local))
        return out
