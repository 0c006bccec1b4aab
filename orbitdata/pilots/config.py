"""Settings of the three pilot levels (recorded in every dataset's metadata)."""

from __future__ import annotations

from dataclasses import dataclass, field

from orbitdata.pilots.control import ControlGains
from orbitdata.pilots.planner import PlannerConfig
from orbitdata.pilots.trajectory import TrajectoryConfig


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
class PilotsConfig:
    gains: ControlGains = field(default_factory=ControlGains)
    expert: ExpertConfig = field(default_factory=ExpertConfig)
    risky: RiskyConfig = field(default_factory=RiskyConfig)
    exploratory: ExploratoryConfig = field(default_factory=ExploratoryConfig)
