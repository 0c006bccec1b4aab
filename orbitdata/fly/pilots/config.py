"""Settings of the three pilot levels (recorded in every dataset's metadata), written once.

Plain frozen dataclasses with no heavy imports: ``orbitdata.config`` builds on them without
loading OMPL or SciPy.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class ControlGains:
    """PD gains on accelerations (scaled by the current mass and inertia) and their caps."""

    pos_kp: float = 2.0  # 1/s^2
    pos_kd: float = 2.8  # 1/s
    max_accel: float = 3.0  # m/s^2, commanded translational acceleration cap
    att_kp: float = 16.0  # 1/s^2
    att_kd: float = 7.0  # 1/s
    max_alpha: float = 20.0  # rad/s^2, commanded angular acceleration cap


@dataclass(frozen=True)
class PlannerConfig:
    """RRT* settings. Lengths in metres."""

    margin: float = 0.35  # safety margin the caller adds to the body radius
    # RRT* iteration budget: deterministic, unlike wall time. 600 kept every expert
    # success on the evaluation grid and plans faster than 1500.
    iterations: int = 600
    max_range: float = 1.5  # RRT* extension range
    goal_bias: float = 0.05  # probability that a sample is the goal point
    bounds_pad: float = 4.0  # sampling box = bbox(start, goal) padded by this
    resolution: float = 0.05  # motion-check step where the clearance bound is smaller

    def __post_init__(self) -> None:
        if self.iterations < 0:
            raise ValueError(f"planner.iterations must be >= 0, got {self.iterations}")
        for name in ("max_range", "resolution"):
            if not getattr(self, name) > 0:
                raise ValueError(f"planner.{name} must be > 0, got {getattr(self, name)}")
        if not (0.0 <= self.goal_bias <= 1.0):
            raise ValueError(f"planner.goal_bias must be in [0, 1], got {self.goal_bias}")
        if self.margin < 0 or self.bounds_pad < 0:
            raise ValueError("planner.margin and planner.bounds_pad must be >= 0")


@dataclass(frozen=True)
class TrajectoryConfig:
    """The expert's timed reference: speeds, accelerations, corner rounding, sampling."""

    cruise_speed: float = 2.0  # m/s
    max_accel: float = 1.5  # m/s^2 along-track accel/decel limit
    max_lateral_accel: float = 1.5  # m/s^2 on corners (v^2 * curvature <= this)
    corner_radius: float = 0.6  # m, largest radius used to round a corner
    spacing: float = 0.05  # m, sample spacing of the reference
    goal_speed: float = 0.5  # m/s at the goal (the goal is a region we fly into)

    def __post_init__(self) -> None:
        for name in ("cruise_speed", "max_accel", "max_lateral_accel", "spacing"):
            if not getattr(self, name) > 0:
                raise ValueError(f"trajectory.{name} must be > 0, got {getattr(self, name)}")
        if self.corner_radius < 0 or self.goal_speed < 0:
            raise ValueError("trajectory.corner_radius and trajectory.goal_speed must be >= 0")


@dataclass(frozen=True)
class ExpertConfig:
    """RRT* on obstacles inflated by the hull's bounding radius + ``planner.margin``,
    shortened, rounded and time-parametrised, tracked by PD with low Gaussian thrust noise."""

    planner: PlannerConfig = field(default_factory=PlannerConfig)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    lookahead: float = 0.3  # m ahead of the closest reference point for camera pointing
    noise_std: float = 0.02  # normalised thrust, i.i.d. per step and thruster


@dataclass(frozen=True)
class RiskyConfig:
    """PD straight to the goal, blind to obstacles."""

    cruise: float = 2.0  # m/s; the initial speed if that is faster


@dataclass(frozen=True)
class ExploratoryConfig:
    """Ornstein-Uhlenbeck noise on the goal-seeking PD (see ExploratoryPilot)."""

    cruise: float = 1.5  # m/s
    accel_sigma: float = 1.5  # m/s^2 on the commanded acceleration
    alpha_sigma: float = 6.0  # rad/s^2 on the commanded angular acceleration
    thrust_sigma: float = 0.05  # normalised thrust, on every thruster
    tau: float = 0.6  # s, noise correlation time


@dataclass(frozen=True)
class DynamicExpertConfig:
    """The dynamic tier's expert: MPPI over world-frame acceleration sequences, each flown in its
    rollout by the attitude PD and the episode's own thrust allocation, with the true body, fault
    and orbit (see :mod:`orbitdata.fly.pilots.dynamic_expert`). Lengths in metres, times in
    control steps of 0.04 s unless named otherwise; costs are unitless weights, per control step.
    ``make_pilot("expert", config)`` flies ``config.pilots.dynamic_expert`` on the dynamic tier
    (a TOML's ``[pilots.dynamic_expert]``; a static-tier dataset's record leaves it out, byte for byte).
    """

    samples: int = 48  # K candidate sequences per replan (the warm start and the fan included)
    horizon: int = 30  # control steps per rollout (1.2 s)
    stride: int = 2  # control steps per rollout step: the plan holds each acceleration this long
    replan_every: int = 8  # control steps between replans while the path ahead is clear ...
    replan_near: int = 2  # ... and while the best candidate passes within ``margin`` of debris
    knot_every: int = 5  # control steps between the knots of a random perturbation
    sample_std: float = 1.5  # m/s^2, standard deviation of a knot's perturbation
    max_accel: float = 3.0  # m/s^2, cap on a commanded acceleration
    temperature: float = 5.0  # lambda of the softmin weights, in cost units
    cruise: float = 2.0  # m/s; the initial speed if that is faster
    max_speed: float = 3.5  # m/s, faster is penalised
    look_bias: float = 0.3  # m/s of goal direction added to the velocity the camera looks along
    # Cost weights.
    goal: float = 1.0  # per metre to the goal, per step until it is reached
    terminal: float = 10.0  # per metre to the goal at the horizon's end, when not reached
    collision: float = 1.0e4  # once, for a rollout that touches debris (earlier costs more)
    clearance: float = 200.0  # per step, times (margin - clearance)^2 within the margin
    margin: float = 0.4  # m of hull clearance below which the clearance cost applies
    contact: float = 0.03  # m of hull clearance that counts as a collision in a rollout
    effort: float = 0.1  # per unit of thrust (sum over thrusters) per step
    attitude: float = 1.0  # per step, times 1 - cos(angle between camera axis and velocity)
    speed: float = 10.0  # per step, times (speed - max_speed)^2 above max_speed
    noise_std: float = 0.02  # normalised thrust, i.i.d. per step and thruster, as the static expert's

    def __post_init__(self) -> None:
        for name in ("horizon", "stride", "replan_every", "replan_near", "knot_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"dynamic_expert.{name} must be >= 1, got {getattr(self, name)}")
        if self.samples < 2:
            raise ValueError(f"dynamic_expert.samples must be >= 2, got {self.samples}")
        for name in ("sample_std", "max_accel", "temperature", "cruise", "max_speed"):
            if not getattr(self, name) > 0:
                raise ValueError(f"dynamic_expert.{name} must be > 0, got {getattr(self, name)}")
        for name in ("goal", "terminal", "collision", "clearance", "margin", "contact", "effort", "attitude"):
            if getattr(self, name) < 0:
                raise ValueError(f"dynamic_expert.{name} must be >= 0, got {getattr(self, name)}")
        if self.speed < 0 or self.noise_std < 0 or self.look_bias < 0:
            raise ValueError("dynamic_expert.speed, noise_std and look_bias must be >= 0")


@dataclass(frozen=True)
class PilotsConfig:
    """The settings of every built-in pilot: shared PD gains, then one section per level, and the
    dynamic tier's expert (recorded only in a dynamic-tier dataset's ``meta/info.json``)."""

    gains: ControlGains = field(default_factory=ControlGains)
    expert: ExpertConfig = field(default_factory=ExpertConfig)
    risky: RiskyConfig = field(default_factory=RiskyConfig)
    exploratory: ExploratoryConfig = field(default_factory=ExploratoryConfig)
    dynamic_expert: DynamicExpertConfig = field(default_factory=DynamicExpertConfig)
