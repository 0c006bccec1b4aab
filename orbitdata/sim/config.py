"""The CubeSat's hardware numbers and the simulation settings, written once.

Reference: the Space Robotics Bench CubeSat used by the Orbit-Planner paper (1U body,
8 corner thrusters at +-0.05 m, 5 N each, directions (0.5 sx, 0.5 sy, sz) normalised).
One change: each thruster is canted by ``cant_deg`` about the body z axis, the sign
alternating around each ring (sx * sy * sz). The reference layout has no yaw authority (its
wrench matrix has rank 5), so it could not point the camera; with the cant the matrix has
rank 6 and its columns positively span R^6 (all-equal thrusts give zero wrench), so every
force/torque direction is achievable with thrusts >= 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from orbitdata.schema import DT

G0 = 9.80665  # m/s^2, standard gravity (defines specific impulse)


@dataclass(frozen=True)
class CubeSatConfig:
    """Body, propulsion and tank. SI units: m, kg, N, s."""

    half_size: float = 0.05  # m, 1U cube of 0.1 m
    dry_mass: float = 1.0  # kg
    fuel_mass: float = 0.33  # kg at a full tank (1.33 kg wet, the 1U CubeSat limit)
    max_thrust: float = 5.0  # N per thruster
    isp: float = 70.0  # s, cold-gas specific impulse: mass flow = thrust / (isp * g0)
    cant_deg: float = 30.0  # thruster cant about body z (see module docstring)
    tank_radius: float = 0.035  # m, fuel modelled as a solid sphere at the centre

    def mass_properties(self, fuel_kg: float) -> tuple[float, float]:
        """(mass kg, principal inertia kg m^2) with ``fuel_kg`` in the tank.

        Solid cube plus a solid spherical tank at the centre: the inertia is isotropic.
        """
        dry_inertia = self.dry_mass * (2 * self.half_size) ** 2 / 6.0
        return self.dry_mass + fuel_kg, dry_inertia + 0.4 * fuel_kg * self.tank_radius**2

    @property
    def mass_flow_per_thrust(self) -> float:
        """kg/s of propellant per unit of normalised thrust (a full command of ``max_thrust``)."""
        return self.max_thrust / (self.isp * G0)

    @property
    def bounding_radius(self) -> float:
        """m, radius of the hull's bounding sphere (the cube's half-diagonal)."""
        return math.sqrt(3.0) * self.half_size


@dataclass(frozen=True)
class CameraConfig:
    """Onboard camera on the +x face, looking along body +x, image up = body +z."""

    image_size: int = 224  # px, square (ViT-tiny/14 expects 224)
    fovy_deg: float = 100.0  # square image: horizontal = vertical field of view
    near: float = 0.1  # m
    far: float = 50.1  # m; farther (or empty space) is "no return" (depth 0)


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings.

    Attributes:
        dt: control period in seconds: 0.04 (25 Hz, the paper's rate), fixed by the schema
            (timestamps, fps, the validator's kinematics), so any other value is refused.
        substeps: physics steps per control step (timestep = dt / substeps).
        max_steps: frames per episode at most (timeout at the last one).
        render: render RGB + depth each step (False for physics-only use).
        gl_backend: 'egl' (default), 'osmesa', or None to honour $MUJOCO_GL.
    """

    cubesat: CubeSatConfig = field(default_factory=CubeSatConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    dt: float = DT
    substeps: int = 8
    max_steps: int = 300
    render: bool = True
    gl_backend: str | None = None

    def __post_init__(self) -> None:
        if abs(self.dt - DT) > 1e-12:
            raise ValueError(
                f"sim.dt must be {DT:g} s (the schema's {1 / DT:g} Hz: timestamps, fps and validation "
                f"follow it), got {self.dt}; change substeps for a finer physics step"
            )
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps}")
        if self.max_steps < 2:
            raise ValueError(f"max_steps must be >= 2, got {self.max_steps}")
        if not 8 <= self.camera.image_size <= 2048:
            raise ValueError(f"image_size must be in [8, 2048] px, got {self.camera.image_size}")
        if self.camera.image_size % 16:
            raise ValueError(
                f"image_size must be a multiple of 16 (depth_low pools to 16x16), got {self.camera.image_size}"
            )
