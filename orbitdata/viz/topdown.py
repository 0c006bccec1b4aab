"""A top-down (x-y) map of an episode drawn with OpenCV: obstacles to scale, goal, path."""

from __future__ import annotations

import cv2
import numpy as np

from orbitdata.scenario.spec import Scenario

BG = (18, 18, 24)
PATH = (80, 200, 255)
GOAL = (90, 220, 90)
HIT = (60, 60, 255)


class TopDownMap:
    """Maps world x-y metres to pixels with a margin around start, goal and obstacles."""

    def __init__(self, scenario: Scenario, size: int, extra_points: np.ndarray | None = None):
        pts = [np.zeros(2), np.asarray(scenario.goal[:2])]
        for ob in scenario.obstacles:
            r = ob.bounding_radius
            c = np.asarray(ob.center[:2])
            pts += [c - r, c + r]
        if extra_points is not None and len(extra_points):
            pts += list(np.asarray(extra_points)[:, :2])
        pts = np.array(pts)
        lo, hi = pts.min(0) - 1.0, pts.max(0) + 1.0
        self.scale = (size - 1) / float(np.max(hi - lo))  # px per metre
        self.lo = lo - ((size - 1) / self.scale - (hi - lo)) / 2  # centre the content
        self.size = size
        self.scenario = scenario

    def px(self, xy) -> tuple[int, int]:
        u = (np.asarray(xy[:2]) - self.lo) * self.scale
        return int(round(u[0])), int(round(self.size - 1 - u[1]))  # image y grows downwards

    def background(self) -> np.ndarray:
        img = np.full((self.size, self.size, 3), BG, np.uint8)
        # 1 m grid
        for k in range(int(np.floor(self.lo[0])), int(np.ceil(self.lo[0] + self.size / self.scale)) + 1):
            x = self.px((k, self.lo[1]))[0]
            cv2.line(img, (x, 0), (x, self.size - 1), (32, 32, 40), 1)
        for k in range(int(np.floor(self.lo[1])), int(np.ceil(self.lo[1] + self.size / self.scale)) + 1):
            y = self.px((self.lo[0], k))[1]
            cv2.line(img, (0, y), (self.size - 1, y), (32, 32, 40), 1)
        for ob in self.scenario.obstacles:
            colour = tuple(int(255 * c) for c in ob.rgba[:3])
            cv2.fillPoly(img, [self._footprint(ob)], colour, lineType=cv2.LINE_AA)
        cv2.circle(img, self.px(self.scenario.goal), max(2, int(self.scenario.goal_radius * self.scale)), GOAL, 2, cv2.LINE_AA)
        cv2.drawMarker(img, self.px((0, 0)), (255, 255, 255), cv2.MARKER_CROSS, 10, 2)
        return img

    def _footprint(self, ob) -> np.ndarray:
        """Outline of the obstacle's projection on x-y: sample its surface and take the hull."""
        u = np.linspace(0, 2 * np.pi, 24)
        v = np.linspace(-np.pi / 2, np.pi / 2, 12)
        uu, vv = np.meshgrid(u, v)
        a, b, c = ob.size
        if ob.shape in ("sphere",):
            a = b = c = ob.size[0]
        if ob.shape in ("capsule", "cylinder"):
            a, b, c = ob.size[0], ob.size[0], ob.size[1] + (ob.size[0] if ob.shape == "capsule" else 0)
        if ob.shape in ("box", "cylinder"):
            # corners/rims: use a box-ish superellipsoid sampling
            pts = np.array([[sx * a, sy * b, sz * c] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
            if ob.shape == "cylinder":
                ang = np.linspace(0, 2 * np.pi, 24)
                pts = np.array([[a * np.cos(t), b * np.sin(t), sz * c] for t in ang for sz in (-1, 1)])
        else:
            pts = np.stack([a * np.cos(vv) * np.cos(uu), b * np.cos(vv) * np.sin(uu), c * np.sin(vv)], -1).reshape(-1, 3)
        world = pts @ ob.rotation.T + np.asarray(ob.center)
        pix = np.array([self.px(p) for p in world], dtype=np.int32)
        return cv2.convexHull(pix)

    def draw_path(self, img: np.ndarray, positions: np.ndarray, collision_at: np.ndarray | None = None) -> np.ndarray:
        if len(positions) > 1:
            pts = np.array([self.px(p) for p in positions], dtype=np.int32)
            cv2.polylines(img, [pts], False, PATH, 2, cv2.LINE_AA)
        if len(positions):
            cv2.circle(img, self.px(positions[-1]), 4, (255, 255, 255), -1, cv2.LINE_AA)
        if collision_at is not None:
            cv2.drawMarker(img, self.px(collision_at), HIT, cv2.MARKER_TILTED_CROSS, 14, 3)
        return img
