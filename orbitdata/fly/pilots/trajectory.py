"""Turn a waypoint polyline into a flyable, arc-length-parametrised reference.

Corners are rounded with circular arcs tangent to both segments (radius up to
``corner_radius``, limited so that neighbouring corners never overlap and, when obstacles are
given, so that the arc keeps clearance > inflation). The speed profile is the usual
forward/backward pass: at most ``cruise_speed``, at most sqrt(max_lateral_accel * R) on an arc,
|d(v^2)/ds| <= 2 max_accel, starting at the current speed and ending at ``goal_speed``.
Everything is deterministic.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from orbitdata.fly.pilots.config import TrajectoryConfig
from orbitdata.scenario.geometry import clearance
from orbitdata.scenario.spec import Obstacle

_MIN_TURN = 1e-6  # rad; smaller deflections are treated as straight
_SHRINKS = 8  # halvings of a corner radius tried before giving up on rounding it


class Trajectory:
    """A dense reference: M samples, equally spaced in arc length, with a speed profile."""

    window: float = 2.0  # m of arc length that closest() searches ahead of its hint

    def __init__(self, points, tangents, normals, curvature, s, speed) -> None:
        self.points = points  # (M, 3) m
        self.tangents = tangents  # (M, 3) unit
        self.normals = normals  # (M, 3) unit towards the centre of curvature, 0 on straights
        self.curvature = curvature  # (M,) 1/m
        self.s = s  # (M,) m of arc length from the start
        self.speed = speed  # (M,) m/s
        ds = np.diff(s)
        v2 = speed**2
        # Along-track acceleration v dv/ds (m/s^2) of the interval that starts at each sample.
        along = np.divide(np.diff(v2), 2.0 * ds, out=np.zeros_like(ds), where=ds > 0)
        self.along_accel = np.append(along, along[-1] if len(along) else 0.0)
        mean_v = 0.5 * (speed[1:] + speed[:-1])
        dt = np.divide(ds, mean_v, out=np.zeros_like(ds), where=mean_v > 0)
        self.t = np.concatenate([[0.0], np.cumsum(dt)])  # (M,) s at each sample
        self.duration = float(self.t[-1])
        step = float(ds.mean()) if len(ds) else 1.0
        self._window_n = max(2, int(math.floor(self.window / max(step, 1e-9) + 1e-9)) + 1)
        for a in (
            self.points,
            self.tangents,
            self.normals,
            self.curvature,
            self.s,
            self.speed,
            self.along_accel,
            self.t,
        ):
            a.setflags(write=False)

    def __len__(self) -> int:
        return len(self.s)

    def closest(self, p, hint: int = 0) -> int:
        """Index of the sample closest to ``p`` among the next ``window`` metres from ``hint``.

        Searching only forward keeps progress monotone: a path that doubles back near
        itself cannot make the reference jump backwards.
        """
        i0 = min(max(int(hint), 0), len(self.s) - 1)
        seg = self.points[i0 : i0 + self._window_n]
        d2 = np.sum((seg - np.asarray(p, dtype=np.float64)) ** 2, axis=1)
        return i0 + int(np.argmin(d2))

    def reference(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position m, velocity m/s, feedforward acceleration m/s^2) at sample ``i``."""
        i = min(max(int(i), 0), len(self.s) - 1)
        v = float(self.speed[i])
        acc = self.along_accel[i] * self.tangents[i] + v * v * self.curvature[i] * self.normals[i]
        return self.points[i].copy(), v * self.tangents[i], acc


def _arc_margin_ok(free, center, e1, e2, radius, theta, step_min) -> bool:
    """Sphere-trace the arc as the planner traces segments (arc length >= chord length)."""
    length = radius * theta

    def point(u: float):
        a = u / radius
        c, s = math.cos(a), math.sin(a)
        return [center[k] + radius * (c * e1[k] + s * e2[k]) for k in range(3)]

    u, m = 0.0, free(point(0.0))
    if m <= 0:
        return False
    while u + m <= length:
        u_next = min(length, u + max(m, step_min))
        m_next = free(point(u_next))
        if m_next <= 0 or m + m_next <= u_next - u:
            return False
        u, m = u_next, m_next
    return True


def _pieces(pts: np.ndarray, cfg: TrajectoryConfig, free):
    """Lines and arcs: ('line', p0, p1) or ('arc', centre, e1, e2, R, theta); plus kinks."""
    pieces, kinks = [], []  # kinks: (piece index the vertex starts, deflection rad)
    seg = np.diff(pts, axis=0)
    lens = np.linalg.norm(seg, axis=1)
    dirs = seg / lens[:, None]
    cur = pts[0]
    for i in range(1, len(pts) - 1):
        u1, u2 = dirs[i - 1], dirs[i]
        theta = math.acos(min(1.0, max(-1.0, float(u1 @ u2))))
        if theta < _MIN_TURN:
            continue
        # Half of each neighbouring segment is this corner's, so arcs never overlap.
        t_max = 0.5 * min(lens[i - 1], lens[i])
        radius = min(cfg.corner_radius, t_max / math.tan(theta / 2)) if theta < math.pi else 0.0
        arc = None
        for _ in range(_SHRINKS):
            if radius < 1e-4:
                break
            tan_len = radius * math.tan(theta / 2)
            p_in = pts[i] - u1 * tan_len
            bis = (u2 - u1) / np.linalg.norm(u2 - u1)
            center = pts[i] + bis * (radius / math.cos(theta / 2))
            e1 = (p_in - center) / radius
            if free is None or _arc_margin_ok(free, center, e1, u1, radius, theta, cfg.spacing / 10):
                arc = ("arc", center, e1, u1.copy(), radius, theta, p_in, pts[i] + u2 * tan_len)
                break
            radius *= 0.5
        if arc is None:  # a sharp corner: the polyline itself is the only curve known to be free
            if np.linalg.norm(pts[i] - cur) > 0:
                pieces.append(("line", cur, pts[i].copy()))
            kinks.append((len(pieces), theta))
            cur = pts[i]
            continue
        if np.linalg.norm(arc[6] - cur) > 0:
            pieces.append(("line", cur, arc[6]))
        pieces.append(arc[:6])
        cur = arc[7]
    if np.linalg.norm(pts[-1] - cur) > 0 or not pieces:
        pieces.append(("line", cur, pts[-1].copy()))
    return pieces, kinks


def _piece_length(p) -> float:
    return float(np.linalg.norm(p[2] - p[1])) if p[0] == "line" else p[4] * p[5]


def time_parametrise(
    path: np.ndarray,
    v0: float,
    config: TrajectoryConfig,
    obstacles: Sequence[Obstacle] | None = None,
    inflation: float | None = None,
) -> Trajectory:
    """Round the corners of ``path`` ((N, 3) m) and give it a speed profile from ``v0`` (m/s).

    With ``obstacles`` and ``inflation`` a corner is rounded less (or not at all) where its arc
    would come within ``inflation`` of an obstacle; the straight parts are the input's own.
    A corner left sharp gets the speed of an arc one sample spacing long, since the
    feedforward cannot represent a kink.
    """
    cfg = config
    pts = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise ValueError("path must be a non-empty (N, 3) array of finite numbers")
    if not (math.isfinite(v0) and v0 >= 0):
        raise ValueError(f"v0 must be a finite speed >= 0, got {v0}")
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9])
    pts = pts[keep]
    if len(pts) == 1:  # already at the goal: a single sample, no motion
        z = np.zeros((1, 3))
        return Trajectory(
            pts.copy(), np.array([[1.0, 0.0, 0.0]]), z, np.zeros(1), np.zeros(1), np.array([float(cfg.goal_speed)])
        )
    free = None
    if obstacles is not None and inflation is not None and len(obstacles) > 0:
        # The 1 nm guard keeps the numpy-evaluated samples strictly valid despite rounding.
        free = lambda p: clearance(obstacles, p) - inflation - 1e-9  # noqa: E731

    pieces, kinks = _pieces(pts, cfg, free)
    lengths = np.array([_piece_length(p) for p in pieces])
    ends = np.cumsum(lengths)
    total = float(ends[-1])
    n = max(2, int(math.ceil(total / cfg.spacing)) + 1)
    s = np.linspace(0.0, total, n)
    ds = total / (n - 1)
    idx = np.minimum(np.searchsorted(ends, s, side="right"), len(pieces) - 1)
    points, tangents, normals = np.empty((n, 3)), np.empty((n, 3)), np.zeros((n, 3))
    curvature = np.zeros(n)
    cap_curv = np.zeros(n)  # curvature the speed must respect near each sample, 1/m
    starts = ends - lengths
    for k, p in enumerate(pieces):
        sel = idx == k
        u = s[sel] - starts[k]
        if p[0] == "line":
            d = (p[2] - p[1]) / lengths[k]
            points[sel] = p[1] + u[:, None] * d
            tangents[sel] = d
            continue
        _, center, e1, e2, radius, _ = p
        a = (u / radius)[:, None]
        radial = np.cos(a) * e1 + np.sin(a) * e2
        points[sel] = center + radius * radial
        tangents[sel] = -np.sin(a) * e1 + np.cos(a) * e2
        normals[sel] = -radial
        curvature[sel] = 1.0 / radius
        # An arc shorter than the spacing may hold no sample: cap its neighbours too.
        near = (s >= starts[k] - ds) & (s <= ends[k] + ds)
        cap_curv[near] = np.maximum(cap_curv[near], 1.0 / radius)
    for k, theta in kinks:
        near = np.abs(s - (starts[k] if k < len(pieces) else total)) <= ds
        cap_curv[near] = np.maximum(cap_curv[near], theta / cfg.spacing)
    points[0], points[-1] = pts[0], pts[-1]  # exact endpoints despite rounding in s

    vmax = np.full(n, float(cfg.cruise_speed))
    bend = cap_curv > 0
    vmax[bend] = np.minimum(vmax[bend], np.sqrt(cfg.max_lateral_accel / cap_curv[bend]))
    v = vmax.copy()
    v[0], v[-1] = float(v0), float(cfg.goal_speed)
    two_a_ds = 2.0 * cfg.max_accel * ds
    vl = v.tolist()
    for i in range(1, n):  # accelerate from v0
        vl[i] = min(vl[i], math.sqrt(vl[i - 1] ** 2 + two_a_ds))
    for i in range(n - 2, 0, -1):  # brake into corners and the goal (v0 itself is given)
        vl[i] = min(vl[i], math.sqrt(vl[i + 1] ** 2 + two_a_ds))
    for i in range(1, n):  # a v0 too high to shed in time: brake as hard as allowed instead
        vl[i] = max(vl[i], math.sqrt(max(vl[i - 1] ** 2 - two_a_ds, 0.0)))
    vl[-1] = float(cfg.goal_speed)  # differs only if the path is too short to reach it
    return Trajectory(points, tangents, normals, curvature, s, np.array(vl))
