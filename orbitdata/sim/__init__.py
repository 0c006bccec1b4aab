"""The simulated world: a CubeSat in MuJoCo, its thrusters, fuel and onboard camera."""

from orbitdata.sim.config import CameraConfig, CubeSatConfig, SimConfig
from orbitdata.sim.env import CubeSatEnv, validate_action
from orbitdata.sim.thrusters import thruster_layout, wrench_matrix

__all__ = [
    "CameraConfig",
    "CubeSatConfig",
    "CubeSatEnv",
    "SimConfig",
    "thruster_layout",
    "validate_action",
    "wrench_matrix",
]
