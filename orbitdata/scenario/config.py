"""Scenario randomisation settings: every number, written once, with paper-like defaults."""

from __future__ import annotations

from dataclasses import dataclass

from orbitdata.schema import SHAPES


@dataclass(frozen=True)
class ScenarioConfig:
    """How episodes are randomised. Lengths in metres, speeds in m/s, angles in degrees.

    Attributes:
        n_obstacles: inclusive (min, max) number of obstacles per episode.
        shapes: obstacle shapes drawn uniformly.
        obstacle_scale: (min, max) characteristic size (radius or half-extent) of an obstacle.
        goal_distance: (min, max) straight-line distance from the start to the goal.
        goal_cone_deg: the goal lies within this angle of the camera's initial axis (+x).
        goal_radius: radius of the goal region.
        speed: (min, max) initial speed v0.
        velocity_cone_deg: the initial velocity points within this angle of the goal.
        attitude_jitter_deg: max initial roll / pitch / yaw away from identity.
        on_line_prob: chance that an obstacle sits on the start-goal line (centre within
            ``on_line_offset`` of its size from the line), which makes straight flight unsafe.
        on_line_offset: lateral offset of on-line obstacles as a fraction of their size.
        corridor_halfwidth: other obstacles sit within this distance of the line.
        along_range: obstacles sit between these fractions of the way to the goal.
        start_clearance: min distance from the start point to any obstacle surface.
        goal_clearance: min distance from the goal region to any obstacle surface.
        sun_intensity, ambient: (min, max) light levels (MuJoCo diffuse / ambient, 0..1).
        max_tries: placement attempts per obstacle before the spec is declared impossible.
    """

    n_obstacles: tuple[int, int] = (1, 5)
    shapes: tuple[str, ...] = SHAPES
    obstacle_scale: tuple[float, float] = (0.4, 1.1)
    goal_distance: tuple[float, float] = (8.0, 12.0)
    goal_cone_deg: float = 25.0
    goal_radius: float = 0.5
    speed: tuple[float, float] = (0.5, 2.5)
    velocity_cone_deg: float = 8.0
    attitude_jitter_deg: float = 10.0
    on_line_prob: float = 0.6
    on_line_offset: float = 0.5
    corridor_halfwidth: float = 3.0
    along_range: tuple[float, float] = (0.3, 0.8)
    start_clearance: float = 2.0
    goal_clearance: float = 1.0
    sun_intensity: tuple[float, float] = (0.7, 1.4)
    ambient: tuple[float, float] = (0.1, 0.35)
    max_tries: int = 200

    def __post_init__(self) -> None:
        lo, hi = self.n_obstacles
        if not 0 <= lo <= hi:
            raise ValueError(f"n_obstacles must be 0 <= min <= max, got {self.n_obstacles}")
        for name in ("obstacle_scale", "goal_distance", "speed", "along_range", "sun_intensity", "ambient"):
            a, b = getattr(self, name)
            if not 0 <= a <= b:
                raise ValueError(f"scenario.{name} must be 0 <= min <= max, got {(a, b)}")
        unknown = set(self.shapes) - set(SHAPES)
        if unknown or not self.shapes:
            raise ValueError(f"scenario.shapes must be a non-empty subset of {SHAPES}, got {self.shapes}")
