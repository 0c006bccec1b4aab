"""Signed distances from a point to obstacle surfaces, in pure Python for speed.

The planner calls these tens of thousands of times per episode, so they avoid numpy's
per-call overhead. Every function is exact except the ellipsoid, where it returns a lower
bound (conservative: a planner using it never gets closer than it thinks).
"""

from __future__ import annotations

import math
from typing import Sequence

from orbitdata.scenario.spec import Obstacle


def _local(ob: Obstacle, p: Sequence[float]) -> tuple[float, float, float]:
    """Point ``p`` (world) in the obstacle's own frame: R^T (p - c)."""
    dx, dy, dz = p[0] - ob.center[0], p[1] - ob.center[1], p[2] - ob.center[2]
    w, x, y, z = ob.quat
    # R^T applied via the conjugate quaternion, written out.
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return (
        r00 * dx + r10 * dy + r20 * dz,
        r01 * dx + r11 * dy + r21 * dz,
        r02 * dx + r12 * dy + r22 * dz,
    )


def signed_distance(ob: Obstacle, p: Sequence[float]) -> float:
    """Distance in metres from point ``p`` to the surface of ``ob``; negative inside."""
    x, y, z = _local(ob, p)
    a, b, c = ob.size
    shape = ob.shape
    if shape == "sphere":
        return math.sqrt(x * x + y * y + z * z) - a
    if shape == "box":
        qx, qy, qz = abs(x) - a, abs(y) - b, abs(z) - c
        outside = math.sqrt(max(qx, 0.0) ** 2 + max(qy, 0.0) ** 2 + max(qz, 0.0) ** 2)
        return outside + min(max(qx, qy, qz), 0.0)
    if shape == "capsule":
        zc = min(max(z, -b), b)
        return math.sqrt(x * x + y * y + (z - zc) ** 2) - a
    if shape == "cylinder":
        dr, dz = math.hypot(x, y) - a, abs(z) - b
        return min(max(dr, dz), 0.0) + math.hypot(max(dr, 0.0), max(dz, 0.0))
    # ellipsoid: x -> x / size is (1 / min(size))-Lipschitz, so this bounds the distance below.
    k = math.sqrt((x / a) ** 2 + (y / b) ** 2 + (z / c) ** 2)
    return (k - 1.0) * min(a, b, c)


def clearance(obstacles: Sequence[Obstacle], p: Sequence[float]) -> float:
    """Smallest signed distance from ``p`` to any obstacle (``inf`` with no obstacles)."""
    return min((signed_distance(ob, p) for ob in obstacles), default=math.inf)
