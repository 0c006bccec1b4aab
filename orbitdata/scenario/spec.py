"""Typed, immutable description of one episode's world (obstacles, goal, start, light)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from orbitdata import schema as S
from orbitdata.scenario.config import DYNAMIC, STATIC
from orbitdata.scenario.dynamics import Dynamics
from orbitdata.scenario.motion import free_motion, tumble
from orbitdata.schema import SHAPES
from orbitdata.state import quat_to_matrix


class ImpossibleScenario(ValueError):
    """A scenario spec that cannot be flown (goal inside an obstacle, blocked start)."""


@dataclass(frozen=True)
class Obstacle:
    """A static rock or piece of debris.

    ``size`` follows MuJoCo's geom convention: sphere (r, 0, 0), ellipsoid and box (a, b, c)
    semi-axes / half-extents, capsule and cylinder (radius, half-length along local z, 0).
    Lengths in metres, ``center`` in the world frame relative to the start.
    """

    shape: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    rgba: tuple[float, float, float, float] = (0.5, 0.5, 0.5, 1.0)

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"unknown obstacle shape {self.shape!r}; expected one of {SHAPES}")
        n_sizes = {"sphere": 1, "capsule": 2, "cylinder": 2}.get(self.shape, 3)
        if any(s <= 0 for s in self.size[:n_sizes]):
            raise ValueError(f"obstacle {self.shape} has non-positive size {self.size}")

    @property
    def rotation(self) -> np.ndarray:
        return quat_to_matrix(self.quat)

    @property
    def bounding_radius(self) -> float:
        """Radius of a sphere about ``center`` that contains the obstacle."""
        a, b, c = self.size
        if self.shape == "sphere":
            return a
        if self.shape == "ellipsoid":
            return max(a, b, c)
        if self.shape == "box":
            return float(np.sqrt(a * a + b * b + c * c))
        if self.shape == "capsule":
            return a + b
        return float(np.hypot(a, b))  # cylinder

    @property
    def inscribed_radius(self) -> float:
        """Radius of the largest sphere about ``center`` inside the obstacle."""
        a, b, c = self.size
        if self.shape in ("sphere", "capsule"):
            return a
        if self.shape == "cylinder":
            return min(a, b)
        return min(a, b, c)  # ellipsoid, box


@dataclass(frozen=True)
class Lighting:
    """A directional sun plus ambient light. ``sun_direction`` is where the light travels."""

    sun_direction: tuple[float, float, float] = (0.3, -0.4, -0.866)
    sun_intensity: float = 1.0
    ambient: float = 0.1


@dataclass(frozen=True)
class Scenario:
    """Everything that defines one episode before it is flown.

    The CubeSat starts at the origin (p_0 = 0) with attitude ``initial_quat`` and world-frame
    velocity ``initial_velocity`` (m/s); it succeeds when its centre enters the sphere of
    ``goal_radius`` metres around ``goal``. A dynamic-tier episode has ``dynamics`` (debris
    motion, orbit, body, fault, sensing); its obstacles give their poses at t = 0.
    """

    obstacles: tuple[Obstacle, ...]
    goal: tuple[float, float, float]
    goal_radius: float = 0.5
    initial_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    initial_quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    lighting: Lighting = field(default_factory=Lighting)
    seed: int = 0
    dynamics: Dynamics | None = None

    def __post_init__(self) -> None:
        if self.dynamics is not None and len(self.dynamics.debris) != len(self.obstacles):
            raise ValueError(
                f"a dynamic scenario needs one debris motion per obstacle: {len(self.obstacles)} obstacles, "
                f"{len(self.dynamics.debris)} motions"
            )

    @property
    def tier(self) -> str:
        return STATIC if self.dynamics is None else DYNAMIC

    def obstacle_poses(self, times) -> np.ndarray:
        """(T, N, 7) poses of the N obstacles at ``times`` (T,) s: centre (m, world) and quat (w, x, y, z).

        Exact: free Clohessy-Wiltshire (or straight) drift and constant tumble; constant in the
        static tier. The privileged record that oracles and validation read.
        """
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        poses = np.empty((t.shape[0], len(self.obstacles), 7))
        for i, ob in enumerate(self.obstacles):
            if self.dynamics is None:
                poses[:, i, :3], poses[:, i, 3:] = ob.center, ob.quat
            else:
                motion = self.dynamics.debris[i]
                poses[:, i, :3] = free_motion(ob.center, motion.velocity, t, self.dynamics.n)[0]
                poses[:, i, 3:] = tumble(ob.quat, motion.angular_velocity, t)
        return poses

    def obstacles_at(self, time: float) -> tuple[Obstacle, ...]:
        """The obstacles where they are at ``time`` s (the same shapes, moved)."""
        if self.dynamics is None:
            return self.obstacles
        poses = self.obstacle_poses(time)[0]
        return tuple(
            replace(ob, center=tuple(float(x) for x in pose[:3]), quat=tuple(float(x) for x in pose[3:]))
            for ob, pose in zip(self.obstacles, poses)
        )

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Scenario":
        """From :meth:`to_dict`, or from a row of the episodes table (same field names)."""
        return cls(
            obstacles=tuple(
                Obstacle(**{k: tuple(v) if isinstance(v, list) else v for k, v in o.items()}) for o in d[S.OBSTACLES]
            ),
            goal=tuple(d[S.GOAL]),
            goal_radius=float(d[S.GOAL_RADIUS]),
            initial_velocity=tuple(d[S.INITIAL_VELOCITY]),
            initial_quat=tuple(d[S.INITIAL_QUAT]),
            lighting=Lighting(**{k: tuple(v) if isinstance(v, list) else v for k, v in d[S.LIGHTING].items()}),
            seed=int(d.get(S.SEED, 0)),
            dynamics=Dynamics.from_dict(d["dynamics"]) if d.get("dynamics") is not None else None,
        )
