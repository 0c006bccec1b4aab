"""The dynamic tier's episode record: what moves and what is wrong, drawn before anyone flies.

A dynamic-tier :class:`~orbitdata.scenario.spec.Scenario` carries a :class:`Dynamics`: how each
obstacle drifts and tumbles (its pose at t = 0 is the obstacle's own ``center`` and ``quat``),
whether the Clohessy-Wiltshire terms act, the body's mass, inertia and centre of mass, a thruster
fault and its onset, and the sensing. All of it is privileged: the simulator and the oracles read
it, a learned pilot never does. Frames: world = the Hill frame (see :mod:`orbitdata.scenario.motion`),
body = the cube's geometric centre with +x along the camera axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitdata.schema import ACTION_DIM, DT

Vec3 = tuple[float, float, float]
NO_FAULT = "none"


@dataclass(frozen=True)
class DebrisMotion:
    """How one obstacle moves (its pose at t = 0 is the obstacle's ``center`` and ``quat``).

    ``velocity`` (m/s, world frame, at t = 0) drifts it, under the Clohessy-Wiltshire terms when
    the episode has them; ``angular_velocity`` (rad/s, world frame) turns it at a constant rate.
    An intercepting piece (``intercept``) is at ``aim`` (m, within ``intercept_miss`` of the
    nominal path) at ``crossing_time`` (s), near the time ``t_star`` (s) at which the nominal
    flight passes that point; the three are None for a piece that only drifts.
    """

    velocity: Vec3
    angular_velocity: Vec3 = (0.0, 0.0, 0.0)
    intercept: bool = False
    t_star: float | None = None
    crossing_time: float | None = None
    aim: Vec3 | None = None


@dataclass(frozen=True)
class BodyParameters:
    """The CubeSat as built this episode: ``mass_scale`` on the dry mass, ``inertia_scale`` on each
    principal dry inertia (body x, y, z), and the centre of mass ``com_offset`` (m, body frame)
    from the cube's centre, which stays the state's reference point (the camera and thrusters
    are fixed to the cube). The fuel tank is as configured."""

    mass_scale: float = 1.0
    inertia_scale: Vec3 = (1.0, 1.0, 1.0)
    com_offset: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ThrusterFault:
    """At most one faulty thruster. From the thrust applied at frame ``onset_step`` on (time
    ``onset_step * dt``), thruster ``thruster`` gives: ``off`` nothing, ``scaled`` its command x
    ``level``, ``stuck`` the thrust ``level`` whatever it is commanded. ``none``: no fault
    (``thruster`` -1)."""

    kind: str = NO_FAULT
    thruster: int = -1
    level: float = 1.0
    onset_step: int = 0

    def __post_init__(self) -> None:
        if self.kind == NO_FAULT:
            if self.thruster != -1:
                raise ValueError(f"a fault of kind 'none' names no thruster, got thruster {self.thruster}")
        elif self.kind in ("off", "scaled", "stuck"):
            if not 0 <= self.thruster < ACTION_DIM:
                raise ValueError(f"fault thruster must be in 0..{ACTION_DIM - 1}, got {self.thruster}")
            if not 0.0 <= self.level <= 1.0:
                raise ValueError(f"fault level must be in [0, 1], got {self.level}")
        else:
            raise ValueError(f"unknown fault kind {self.kind!r}; expected none, off, scaled or stuck")
        if self.onset_step < 0:
            raise ValueError(f"fault onset_step must be >= 0, got {self.onset_step}")

    @property
    def onset_time(self) -> float:
        """s, when the fault starts."""
        return self.onset_step * DT

    def active(self, step: int) -> bool:
        """Whether the thrust applied from frame ``step`` to ``step + 1`` is faulty."""
        return self.kind != NO_FAULT and step >= self.onset_step

    def apply(self, thrust: np.ndarray, step: int) -> np.ndarray:
        """The thrusts (8,) the thrusters give for the commanded ``thrust`` (8,) at frame ``step``."""
        if not self.active(step):
            return thrust
        out = np.array(thrust, dtype=np.float64)
        k = self.thruster
        out[k] = {"off": 0.0, "scaled": out[k] * self.level, "stuck": self.level}[self.kind]
        return out


@dataclass(frozen=True)
class Sensing:
    """The camera this episode: Gaussian RGB noise (std in [0, 1] units), the share of depth
    pixels that return nothing, eclipse (no sun: lit by the onboard light alone) and the onboard
    spotlight's diffuse intensity."""

    rgb_noise: float = 0.0
    depth_dropout: float = 0.0
    eclipse: bool = False
    onboard_light: float = 0.0


@dataclass(frozen=True)
class Dynamics:
    """Everything the dynamic tier adds to an episode.

    ``debris`` holds one :class:`DebrisMotion` per obstacle, in the obstacles' order. ``cw``: the
    Clohessy-Wiltshire terms act on the CubeSat and the debris, with mean motion ``mean_motion``
    (rad/s). ``unsurvivable_draws``: debris draws rejected because no pilot within the escape
    acceleration could have survived them (the tier's rejection count).
    """

    debris: tuple[DebrisMotion, ...]
    cw: bool = False
    mean_motion: float = 0.0
    body: BodyParameters = BodyParameters()
    fault: ThrusterFault = ThrusterFault()
    sensing: Sensing = Sensing()
    unsurvivable_draws: int = 0

    @property
    def n(self) -> float:
        """rad/s, the mean motion that acts (0 without the CW terms)."""
        return self.mean_motion if self.cw else 0.0

    @classmethod
    def from_dict(cls, d: dict) -> "Dynamics":
        """From ``dataclasses.asdict`` of a Dynamics (lists stand for tuples)."""

        def tup(v):
            return tuple(v) if isinstance(v, list) else v

        return cls(
            debris=tuple(DebrisMotion(**{k: tup(v) for k, v in m.items()}) for m in d["debris"]),
            cw=bool(d["cw"]),
            mean_motion=float(d["mean_motion"]),
            body=BodyParameters(**{k: tup(v) for k, v in d["body"].items()}),
            fault=ThrusterFault(**d["fault"]),
            sensing=Sensing(**d["sensing"]),
            unsurvivable_draws=int(d["unsurvivable_draws"]),
        )
