"""Orthographic maps of an episode drawn with OpenCV: obstacles to scale, goal, start, path.

On the dynamic tier the obstacles move: the background shows them at their start pose, and
``draw_tracks`` adds each piece's track (its centre over the episode, a dot at the start),
``draw_debris`` the outlines where the pieces are at a frame, ``draw_fault`` where the fault began.

``PlaneMap`` projects the world on two of its axes: ``(0, 1)`` is the top-down view (x right,
y up), ``(0, 2)`` the side view (x right, z up). Images are RGB. The mapping from metres to
pixels is public (``px``, ``polyline``, ``world``) so callers and tests can find what was drawn.
"""

from __future__ import annotations

import cv2
import numpy as np

from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.state import quat_to_matrix

# RGB colours
BG = (18, 18, 24)
GRID = (34, 34, 44)
PATH = (80, 200, 255)
GOAL = (90, 220, 90)
HIT = (255, 60, 60)
START = (255, 255, 255)
HEADING = (255, 210, 60)
TRACK = (190, 140, 255)  # a piece of debris' track and its pose now (dynamic tier)
FAULT = (255, 80, 200)  # where the thruster fault began (dynamic tier)

AXIS_NAMES = "xyz"


def _surface_points(ob: Obstacle) -> np.ndarray:
    """Points whose convex hull is the obstacle, in its own frame. (N, 3) metres."""
    u = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    v = np.linspace(-np.pi / 2, np.pi / 2, 12)
    uu, vv = np.meshgrid(u, v)
    unit = np.stack([np.cos(vv) * np.cos(uu), np.cos(vv) * np.sin(uu), np.sin(vv)], -1).reshape(-1, 3)
    a, b, c = ob.size
    if ob.shape == "sphere":
        return a * unit
    if ob.shape == "ellipsoid":
        return unit * np.array([a, b, c])
    if ob.shape == "box":
        return np.array([[sx * a, sy * b, sz * c] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    if ob.shape == "capsule":  # radius a, half-length b: two spheres joined by their hull
        return np.concatenate([a * unit + [0, 0, b], a * unit - [0, 0, b]])
    ring = np.stack([a * np.cos(u), a * np.sin(u)], -1)  # cylinder: two rims
    return np.concatenate([np.c_[ring, np.full(len(u), b)], np.c_[ring, np.full(len(u), -b)]])


class PlaneMap:
    """Maps world metres on ``axes`` to pixels of a ``size`` (int or (width, height)) image.

    The content (start, goal, obstacles and ``extra_points``, e.g. the path) is fitted with a
    1 m margin and centred; ``scale`` (px per metre) may be given to share it between views.
    """

    def __init__(
        self,
        scenario: Scenario,
        size: int | tuple[int, int],
        extra_points: np.ndarray | None = None,
        axes: tuple[int, int] = (0, 1),
        scale: float | None = None,
        margin: float = 1.0,
    ):
        self.width, self.height = (size, size) if np.isscalar(size) else (int(size[0]), int(size[1]))
        if self.width < 8 or self.height < 8:
            raise ValueError(f"map size {self.width}x{self.height} px is too small; use at least 8x8")
        self.axes = tuple(axes)
        self.scenario = scenario
        ax = list(self.axes)
        goal = np.asarray(scenario.goal, float)[ax]
        pts = [np.zeros(2), goal - scenario.goal_radius, goal + scenario.goal_radius]
        for ob in scenario.obstacles:
            c, r = np.asarray(ob.center, float)[ax], ob.bounding_radius
            pts += [c - r, c + r]
        if extra_points is not None and len(extra_points):
            pts += list(np.asarray(extra_points, float)[:, ax])
        pts = np.array(pts)
        lo, hi = pts.min(0) - margin, pts.max(0) + margin
        span = np.array([self.width - 1, self.height - 1], float)
        self.scale = float(scale) if scale is not None else float(np.min(span / (hi - lo)))  # px per metre
        self.lo = (lo + hi) / 2 - span / self.scale / 2  # world coords of pixel (0, height-1): centred content

    # ---- the mapping ------------------------------------------------------------------------
    def px(self, point) -> tuple[int, int]:
        """Pixel (column, row) of a world point (3-vector, or 2-vector already on ``axes``)."""
        u, v = self.polyline(np.asarray(point, float)[None])[0]
        return int(u), int(v)

    def polyline(self, positions: np.ndarray) -> np.ndarray:
        """(N, 3) world points (or (N, 2) on ``axes``) -> (N, 2) int32 pixel (column, row)."""
        p = np.asarray(positions, float)
        if p.shape[1] == 3:
            p = p[:, list(self.axes)]
        u = (p - self.lo) * self.scale
        return np.stack([np.rint(u[:, 0]), np.rint(self.height - 1 - u[:, 1])], -1).astype(np.int32)

    def world(self, pixels: np.ndarray) -> np.ndarray:
        """(N, 2) pixel (column, row) -> (N, 2) world metres on ``axes``; inverse of ``polyline``."""
        q = np.asarray(pixels, float)
        return np.stack([q[:, 0] / self.scale + self.lo[0], (self.height - 1 - q[:, 1]) / self.scale + self.lo[1]], -1)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """World (left, right, bottom, top) of the pixel centres at the image edges, metres."""
        return (
            self.lo[0],
            self.lo[0] + (self.width - 1) / self.scale,
            self.lo[1],
            self.lo[1] + (self.height - 1) / self.scale,
        )

    @property
    def axis_names(self) -> tuple[str, str]:
        return AXIS_NAMES[self.axes[0]], AXIS_NAMES[self.axes[1]]

    # ---- drawing ----------------------------------------------------------------------------
    def background(self) -> np.ndarray:
        """Grid (1 m), obstacles to scale, goal region and start cross. (H, W, 3) uint8 RGB."""
        img = np.full((self.height, self.width, 3), BG, np.uint8)
        left, right, bottom, top = self.extent
        for k in range(int(np.ceil(left)), int(np.floor(right)) + 1):
            x = self.px((k, 0.0))[0]
            cv2.line(img, (x, 0), (x, self.height - 1), GRID, 1)
        for k in range(int(np.ceil(bottom)), int(np.floor(top)) + 1):
            y = self.px((0.0, k))[1]
            cv2.line(img, (0, y), (self.width - 1, y), GRID, 1)
        for ob in self.scenario.obstacles:
            colour = tuple(int(255 * c) for c in ob.rgba[:3])
            hull = self._footprint(ob)
            cv2.fillPoly(img, [hull], colour, lineType=cv2.LINE_AA)
            cv2.polylines(img, [hull], True, tuple(int(0.6 * c) for c in colour), 1, cv2.LINE_AA)
        radius = max(2, int(round(self.scenario.goal_radius * self.scale)))
        cv2.circle(img, self.px(self.scenario.goal), radius, GOAL, 2, cv2.LINE_AA)
        cv2.drawMarker(img, self.px((0.0, 0.0, 0.0)), START, cv2.MARKER_CROSS, 10, 2)
        return img

    def _footprint(self, ob: Obstacle, pose: np.ndarray | None = None) -> np.ndarray:
        """Outline of the obstacle's projection: the hull of its surface points, at its own pose
        or at ``pose`` (7,): centre (m, world) and quat (w, x, y, z)."""
        center, rotation = (ob.center, ob.rotation) if pose is None else (pose[:3], quat_to_matrix(pose[3:]))
        world = _surface_points(ob) @ rotation.T + np.asarray(center)
        return cv2.convexHull(self.polyline(world))

    def draw_tracks(self, img: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """Each piece's track in place: its centre from the first to the last of ``poses`` (L, N, 7),
        a dot where it started."""
        for i in range(poses.shape[1]):
            track = self.polyline(poses[:, i, :3])
            cv2.polylines(img, [track], False, TRACK, 1, cv2.LINE_AA)
            cv2.circle(img, tuple(int(x) for x in track[0]), 3, TRACK, -1, cv2.LINE_AA)
        return img

    def draw_debris(self, img: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """The outline of every obstacle at ``poses`` (N, 7), e.g. where each piece is at a frame."""
        for ob, pose in zip(self.scenario.obstacles, poses):
            cv2.polylines(img, [self._footprint(ob, pose)], True, TRACK, 1, cv2.LINE_AA)
        return img

    def draw_fault(self, img: np.ndarray, position) -> np.ndarray:
        """A diamond where the CubeSat was when its thruster fault began."""
        cv2.drawMarker(img, self.px(position), FAULT, cv2.MARKER_DIAMOND, 12, 2, cv2.LINE_AA)
        return img

    def draw_path(self, img: np.ndarray, positions: np.ndarray, collision_at: np.ndarray | None = None) -> np.ndarray:
        """Draw the path (N, 3) in place, a dot at its end and a red cross where it collided."""
        if len(positions) > 1:
            cv2.polylines(img, [self.polyline(positions)], False, PATH, 2, cv2.LINE_AA)
        if len(positions):
            cv2.circle(img, self.px(positions[-1]), 4, START, -1, cv2.LINE_AA)
        if collision_at is not None:
            cv2.drawMarker(img, self.px(collision_at), HIT, cv2.MARKER_TILTED_CROSS, 14, 3)
        return img

    def draw_heading(self, img: np.ndarray, position, direction, length_m: float = 1.0) -> np.ndarray:
        """An arrow from ``position`` along the unit vector ``direction`` (e.g. the camera axis)."""
        tip = np.asarray(position, float) + length_m * np.asarray(direction, float)
        cv2.arrowedLine(img, self.px(position), self.px(tip), HEADING, 2, cv2.LINE_AA, tipLength=0.3)
        return img


def paired_views(
    scenario: Scenario, top_size: tuple[int, int], side_size: tuple[int, int], extra_points: np.ndarray | None = None
) -> tuple[PlaneMap, PlaneMap]:
    """A top-down (x-y) and a side (x-z) map at one scale, so lengths compare between them."""
    top = PlaneMap(scenario, top_size, extra_points, (0, 1))
    side = PlaneMap(scenario, side_size, extra_points, (0, 2))
    scale = min(top.scale, side.scale)
    return (
        PlaneMap(scenario, top_size, extra_points, (0, 1), scale=scale),
        PlaneMap(scenario, side_size, extra_points, (0, 2), scale=scale),
    )


def draw_numbered(img: np.ndarray, view: PlaneMap, points: np.ndarray, first: int = 1) -> np.ndarray:
    """Numbered dots at world ``points`` (N, 3): where the contact sheet's key frames were taken."""
    for n, p in enumerate(points, first):
        u, v = view.px(p)
        cv2.circle(img, (u, v), 4, HEADING, -1, cv2.LINE_AA)
        for colour, width in ((BG, 3), (HEADING, 1)):  # a dark rim keeps it readable on light rocks
            cv2.putText(img, str(n), (u + 5, v - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, width, cv2.LINE_AA)
    return img
