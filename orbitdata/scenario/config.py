"""Scenario randomisation settings: every number, written once, with paper-like defaults.

Two named tiers share these settings: ``static`` (the paper's scenes, the default) and
``dynamic`` (drifting, tumbling debris, Clohessy-Wiltshire terms, a varied body, a faulty
thruster and noisy sensing; :class:`DynamicConfig`). :meth:`ScenarioConfig.for_tier` gives a
tier's defaults.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

from orbitdata.schema import SHAPES

STATIC, DYNAMIC = "static", "dynamic"
TIERS = (STATIC, DYNAMIC)
FAULT_KINDS = ("off", "scaled", "stuck")
MAX_OBSTACLES = 1000  # per episode: far beyond any tier's, and a scene MuJoCo still builds in a moment


def _check_range(where: str, name: str, pair, low: float = 0.0, high: float = float("inf")) -> None:
    a, b = pair
    if not low <= a <= b <= high:
        raise ValueError(f"{where}.{name} must be {low:g} <= min <= max <= {high:g}, got {(a, b)}")


@dataclass(frozen=True)
class DynamicConfig:
    """The dynamic tier's draws, used when ``ScenarioConfig.tier == "dynamic"``.

    Lengths in metres, speeds in m/s, rates in degrees/s, times in seconds; probabilities per
    episode (per piece of debris for ``intercept_prob``).

    Attributes:
        debris_speed: (min, max) drift speed of each piece relative to the orbital frame.
        tumble_deg_s: (min, max) tumble rate about a random axis (constant, world frame).
        intercept_prob: chance that a piece is aimed at the nominal start-to-goal flight: it
            crosses a point of that path near the time t* the nominal flight passes it.
        intercept_along: the crossing lies between these fractions of the way to the goal.
        intercept_miss: the aim point lies within this distance of the path (a disc across it).
        intercept_jitter: the piece reaches the aim point within this many seconds of t*.
        nominal_speed: the nominal flight runs straight to the goal at max(v0, this) (the risky
            pilot's cruise).
        escape_accel: a scenario is unsurvivable, and its debris redrawn, when a piece fills every
            point a pilot accelerating at most this hard could reach at some time (the expert's
            planning limit).
        horizon: seconds over which debris is checked against the goal and the escape bound
            (the 300-frame episode).
        cw_prob: chance that an episode carries the Clohessy-Wiltshire (Hill) terms.
        mean_motion: rad/s, n of the reference circular orbit (0.00113 at 400 km).
        mass_scale: (min, max) factor on the dry mass.
        inertia_scale: (min, max) factor on each principal dry inertia, drawn per axis.
        com_offset: (min, max) distance of the centre of mass from the cube's centre.
        fault_prob: chance that one of the eight thrusters is faulty.
        fault_kinds: kinds drawn uniformly: ``off``, ``scaled`` (thrust x ``fault_scale``) or
            ``stuck`` (fires at ``fault_stuck`` whatever it is commanded).
        fault_scale, fault_stuck: (min, max) of the scaled factor and the stuck thrust.
        fault_at_start_prob: chance that the fault is there from t = 0; otherwise it starts at a
            time drawn from ``fault_onset``.
        fault_onset: (min, max) onset time of a fault that starts mid-episode.
        rgb_noise: standard deviation of the Gaussian noise on RGB in [0, 1] units.
        depth_dropout: (min, max) share of depth pixels that return nothing, drawn per episode.
        eclipse_prob: chance that the episode is in eclipse: no sun, lit by the onboard light.
        eclipse_ambient: MuJoCo ambient light in eclipse.
        onboard_light: diffuse intensity of the spotlight beside the camera (every episode).
        max_tries: draws per piece of debris before the spec is declared impossible.
        max_body_rate: rad/s; an episode ends ``tumbling`` when the body's rate exceeds it. A
            fault-blind pilot (risky, exploratory) can spin the body up without bound, and
            MuJoCo's Euler step gains angular momentum the faster the body spins,
            until MuJoCo declares the state unstable and resets it: the limit ends such a flight
            while its physics still holds. About 2000 deg/s, the widest range of common MEMS
            rate gyros, and far above what the expert flies.
    """

    debris_speed: tuple[float, float] = (0.1, 1.0)
    tumble_deg_s: tuple[float, float] = (0.0, 30.0)
    intercept_prob: float = 0.8
    intercept_along: tuple[float, float] = (0.3, 0.8)
    intercept_miss: float = 0.3
    intercept_jitter: float = 0.5
    nominal_speed: float = 2.0
    escape_accel: float = 1.5
    horizon: float = 12.0
    cw_prob: float = 0.5
    mean_motion: float = 0.00113
    mass_scale: tuple[float, float] = (0.8, 1.2)
    inertia_scale: tuple[float, float] = (0.8, 1.2)
    com_offset: tuple[float, float] = (0.01, 0.02)
    fault_prob: float = 0.75
    fault_kinds: tuple[str, ...] = FAULT_KINDS
    fault_scale: tuple[float, float] = (0.3, 0.7)
    fault_stuck: tuple[float, float] = (0.05, 0.10)
    fault_at_start_prob: float = 0.5
    fault_onset: tuple[float, float] = (1.0, 4.0)
    rgb_noise: float = 0.02
    depth_dropout: tuple[float, float] = (0.05, 0.20)
    eclipse_prob: float = 0.25
    eclipse_ambient: float = 0.02
    onboard_light: float = 0.6
    max_tries: int = 200
    max_body_rate: float = 35.0

    def __post_init__(self) -> None:
        where = "scenario.dynamic"
        for name in ("debris_speed", "tumble_deg_s", "com_offset", "fault_onset"):
            _check_range(where, name, getattr(self, name))
        for name in ("intercept_along", "fault_scale", "fault_stuck", "depth_dropout"):
            _check_range(where, name, getattr(self, name), high=1.0)
        _check_range(where, "mass_scale", self.mass_scale, low=0.01)
        _check_range(where, "inertia_scale", self.inertia_scale, low=0.01)
        for name in ("intercept_prob", "cw_prob", "fault_prob", "fault_at_start_prob", "eclipse_prob"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{where}.{name} must be a probability in [0, 1], got {getattr(self, name)}")
        for name in ("nominal_speed", "escape_accel", "horizon", "max_body_rate"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{where}.{name} must be > 0, got {getattr(self, name)}")
        for name in ("intercept_miss", "intercept_jitter", "mean_motion", "rgb_noise", "eclipse_ambient"):
            if getattr(self, name) < 0:
                raise ValueError(f"{where}.{name} must be >= 0, got {getattr(self, name)}")
        unknown = set(self.fault_kinds) - set(FAULT_KINDS)
        if unknown or not self.fault_kinds:
            raise ValueError(f"{where}.fault_kinds must be a non-empty subset of {FAULT_KINDS}, got {self.fault_kinds}")
        if self.max_tries < 1:
            raise ValueError(f"{where}.max_tries must be >= 1, got {self.max_tries}")


@dataclass(frozen=True)
class ScenarioConfig:
    """How episodes are randomised. Lengths in metres, speeds in m/s, angles in degrees.

    Attributes:
        tier: ``static`` (the paper's scenes) or ``dynamic`` (the settings in ``dynamic``); start
            from :meth:`for_tier`, which also sets the tier's obstacle count and speed ranges.
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
        dynamic: the dynamic tier's settings (:class:`DynamicConfig`; unused by ``static``).
    """

    tier: str = STATIC
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
    dynamic: DynamicConfig = field(default_factory=DynamicConfig)

    def __post_init__(self) -> None:
        if self.tier not in TIERS:
            raise ValueError(f"scenario.tier must be one of {', '.join(TIERS)}, got {self.tier!r}")
        lo, hi = self.n_obstacles
        if not 0 <= lo <= hi <= MAX_OBSTACLES:
            raise ValueError(f"n_obstacles must be 0 <= min <= max <= {MAX_OBSTACLES}, got {self.n_obstacles}")
        for name in ("obstacle_scale", "goal_distance", "speed", "along_range", "sun_intensity", "ambient"):
            a, b = getattr(self, name)
            if not 0 <= a <= b:
                raise ValueError(f"scenario.{name} must be 0 <= min <= max, got {(a, b)}")
        unknown = set(self.shapes) - set(SHAPES)
        if unknown or not self.shapes:
            raise ValueError(f"scenario.shapes must be a non-empty subset of {SHAPES}, got {self.shapes}")

    @classmethod
    def for_tier(cls, tier: str, **changes) -> "ScenarioConfig":
        """The defaults of a named tier, with ``changes`` to single fields.

        ``static``: the paper's scenes (``ScenarioConfig()``). ``dynamic``: 1-10 obstacles and
        initial speeds of 0.5-3 m/s, with :class:`DynamicConfig`'s draws.
        """
        if tier not in TIER_DEFAULTS:
            raise ValueError(f"unknown scenario tier {tier!r}; choose one of {', '.join(TIERS)}")
        return replace(cls(), **{**TIER_DEFAULTS[tier], **changes})


# The fields a tier sets beyond ScenarioConfig's defaults (the static tier's).
TIER_DEFAULTS: dict[str, dict] = {
    STATIC: {},
    DYNAMIC: {"tier": DYNAMIC, "n_obstacles": (1, 10), "speed": (0.5, 3.0)},
}
assert set(TIER_DEFAULTS) == set(TIERS)
assert all(set(d) <= {f.name for f in fields(ScenarioConfig)} for d in TIER_DEFAULTS.values())
