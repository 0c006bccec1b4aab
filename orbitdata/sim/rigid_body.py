"""The dynamic tier's CubeSat over one control step, as the simulator integrates it, for many steps at once.

The simulator (:mod:`orbitdata.sim.env`, :mod:`orbitdata.sim.dynamic`) holds the thrust of a step
for its ``n`` substeps of ``h = dt / n``; MuJoCo's semi-implicit Euler updates the velocities with
the accelerations of the substep's start, then the pose with the new velocities. The model here
is that integrator on the rigid body as the episode record draws it:

* thrusts: the command through the recorded fault from its onset frame, scaled down on the step
  that empties the tank; the mass and principal inertia are those of the fuel at the step's
  start (as :func:`orbitdata.sim.dynamic.body_mass_properties` gives them);
* force and torque: the thrusters' body-frame wrench about the centre of mass, offset by
  ``com_offset`` from the cube's centre; Euler's equations for the rotation (the inertia is not
  isotropic, so the gyroscopic term acts);
* the Clohessy-Wiltshire acceleration of the centre of mass when the episode is flagged ``cw``;
* the state's p and v are the cube centre's (MuJoCo's free joint), which moves with the
  centre of mass plus ``w x r``.

The validator checks the dataset against it (:mod:`orbitdata.validate.residuals`) and the
oracles plan with it (:mod:`orbitmodel.plan.true_body`). It is numpy only: it never imports MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np

from orbitdata.scenario.dynamics import NO_FAULT
from orbitdata.scenario.motion import cw_acceleration
from orbitdata.sim.config import CubeSatConfig
from orbitdata.sim.thrusters import wrench_matrix
from orbitdata.state import (
    ANGULAR_VELOCITY,
    FUEL,
    POSITION,
    ROT6D,
    STATE_DIM,
    VELOCITY,
    matrix_to_rot6d,
    rot6d_to_matrix,
)

FAULT_KINDS = (NO_FAULT, "off", "scaled", "stuck")  # codes 0..3 in :class:`StepBody`


@dataclass
class StepBody:
    """The episode record of each step's episode, one row per step (N steps)."""

    mass_scale: np.ndarray  # (N,)
    inertia_scale: np.ndarray  # (N, 3)
    com: np.ndarray  # (N, 3) m, body frame, from the cube's centre
    n: np.ndarray  # (N,) rad/s: the mean motion when the episode is flagged cw, else 0
    fault_kind: np.ndarray  # (N,) int code into FAULT_KINDS
    fault_thruster: np.ndarray  # (N,) int, -1 for none
    fault_level: np.ndarray  # (N,)
    onset: np.ndarray  # (N,) int, the frame from which the fault acts

    @classmethod
    def nominal(cls, rows: int) -> "StepBody":
        """``rows`` steps of the nominal body: no fault, no CW terms."""
        return cls(
            mass_scale=np.ones(rows),
            inertia_scale=np.ones((rows, 3)),
            com=np.zeros((rows, 3)),
            n=np.zeros(rows),
            fault_kind=np.zeros(rows, int),
            fault_thruster=np.full(rows, -1),
            fault_level=np.ones(rows),
            onset=np.zeros(rows, int),
        )

    def fill(self, rows, dynamics) -> None:
        """Set ``rows`` (an index or mask) to the episode record ``dynamics``
        (a :class:`orbitdata.scenario.dynamics.Dynamics`)."""
        self.mass_scale[rows] = dynamics.body.mass_scale
        self.inertia_scale[rows] = dynamics.body.inertia_scale
        self.com[rows] = dynamics.body.com_offset
        self.n[rows] = dynamics.n
        self.fault_kind[rows] = FAULT_KINDS.index(dynamics.fault.kind)
        self.fault_thruster[rows] = dynamics.fault.thruster
        self.fault_level[rows] = dynamics.fault.level
        self.onset[rows] = dynamics.fault.onset_step

    def take(self, index) -> "StepBody":
        return StepBody(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    def replace(self, **changes) -> "StepBody":
        return StepBody(**{f.name: changes.get(f.name, getattr(self, f.name)) for f in fields(self)})


def rows(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N, 3, 3) @ (N, 3) row by row."""
    return np.einsum("nij,nj->ni", M, x)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def given_thrust(action: np.ndarray, frame: np.ndarray, body: StepBody) -> np.ndarray:
    """(N, 8) what the thrusters gave for the commanded ``action`` at ``frame`` (before the fuel limit)."""
    thrust = np.array(action, dtype=np.float64)
    active = (body.fault_kind != 0) & (frame >= body.onset)
    rows = np.flatnonzero(active)
    k = body.fault_thruster[rows]
    commanded = thrust[rows, k]
    kind = body.fault_kind[rows]
    thrust[rows, k] = np.where(
        kind == 1, 0.0, np.where(kind == 2, commanded * body.fault_level[rows], body.fault_level[rows])
    )
    return thrust


@dataclass
class Motion:
    """Where N steps end: cube centre p (m, world), R (body -> world), v of the cube's centre
    (m/s, world) and w (rad/s, body); ``turn`` is h * sum of the substeps' R, the map from a held
    body-frame acceleration to the velocity it adds over the step."""

    p: np.ndarray
    R: np.ndarray
    v: np.ndarray
    w: np.ndarray
    turn: np.ndarray | None = None
    q: np.ndarray | None = None  # (N, 4) the attitude as the integrator carries it, when known


def start_of(state: np.ndarray) -> Motion:
    """The motion of states (N, 16) float64."""
    R = rot6d_to_matrix(state[:, ROT6D])
    return Motion(state[:, POSITION].copy(), R, rows(R, state[:, VELOCITY]), state[:, ANGULAR_VELOCITY].copy())


def state_of(motion: Motion, fuel_ratio: np.ndarray) -> np.ndarray:
    """States (N, 16) float64 of N motions and their fuel ratios: the inverse of :func:`start_of`."""
    out = np.empty((len(motion.p), STATE_DIM))
    out[:, POSITION] = motion.p
    out[:, VELOCITY] = np.einsum("nji,nj->ni", motion.R, motion.v)
    out[:, ROT6D] = matrix_to_rot6d(motion.R)
    out[:, ANGULAR_VELOCITY] = motion.w
    out[:, FUEL.start] = fuel_ratio
    return out


def _matrix(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (w, x, y, z) -> (N, 3, 3) rotations."""
    w, x, y, z = q.T
    return np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        axis=1,
    ).reshape(-1, 3, 3)  # fmt: skip


def _quaternion(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations -> (N, 4) unit quaternions (Shepperd: from the largest of w, x, y, z)."""
    r = R.reshape(-1, 9)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r.T
    big = np.argmax(np.stack([r00 + r11 + r22, r00, r11, r22]), axis=0)
    s = 2.0 * np.sqrt(
        np.maximum(1.0 + np.stack([r00 + r11 + r22, r00 - r11 - r22, r11 - r00 - r22, r22 - r00 - r11]), 1e-300)
    )
    cases = np.stack(
        [
            [s[0] / 4, (r21 - r12) / s[0], (r02 - r20) / s[0], (r10 - r01) / s[0]],
            [(r21 - r12) / s[1], s[1] / 4, (r01 + r10) / s[1], (r02 + r20) / s[1]],
            [(r02 - r20) / s[2], (r01 + r10) / s[2], s[2] / 4, (r12 + r21) / s[2]],
            [(r10 - r01) / s[3], (r02 + r20) / s[3], (r12 + r21) / s[3], s[3] / 4],
        ]
    )  # (case, component, N)
    q = cases[big, :, np.arange(len(r))]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _turn(q: np.ndarray, w: np.ndarray, h: float) -> np.ndarray:
    """q turned by the body-frame angular velocity w for h seconds (MuJoCo's quaternion integration)."""
    angle = h * np.linalg.norm(w, axis=1)
    axis = w * (np.sin(0.5 * angle) / np.where(angle > 0, angle / h, 1.0))[:, None]
    c = np.cos(0.5 * angle)
    qw, qx, qy, qz = q.T
    ax, ay, az = axis.T
    out = np.stack(
        [
            qw * c - qx * ax - qy * ay - qz * az,
            qw * ax + qx * c + qy * az - qz * ay,
            qw * ay - qx * az + qy * c + qz * ax,
            qw * az + qx * ay - qy * ax + qz * c,
        ],
        axis=1,
    )
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def fly(
    start: Motion,
    force: np.ndarray,
    torque: np.ndarray,
    inertia: np.ndarray,
    body: StepBody,
    dt: float,
    substeps: int,
) -> Motion:
    """One control step of N bodies: ``force`` (N, 3) per unit mass and ``torque`` (N, 3) about
    the centre of mass, both body frame and held, ``inertia`` (N, 3) principal (kg m^2)."""
    h = dt / substeps
    p, v, w = start.p, start.v, start.w
    q = _quaternion(start.R) if start.q is None else start.q
    c, n = body.com, body.n
    cw = bool(np.any(n))
    turn = np.zeros_like(start.R)
    for _ in range(substeps):
        R = _matrix(q)
        turn += R
        r = rows(R, c)  # cube centre -> centre of mass, world
        omega = rows(R, w)
        spin = cross(omega, r)
        a_com = rows(R, force)
        if cw:
            a_com = a_com + cw_acceleration(p + r, v + spin, n)
        alpha = (torque - cross(w, inertia * w)) / inertia  # Euler's equations, body frame
        a_centre = a_com - cross(rows(R, alpha), r) - cross(omega, spin)
        v = v + h * a_centre
        w = w + h * alpha
        p = p + h * v
        q = _turn(q, w, h)
    return Motion(p, _matrix(q), v, w, h * turn, q)


def mass_and_inertia(cubesat: CubeSatConfig, body: StepBody, fuel_kg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mass (N,) and principal inertia (N, 3) with ``fuel_kg`` in the tank: the simulator's
    :func:`orbitdata.sim.dynamic.body_mass_properties` (the dry mass and each dry inertia scaled,
    the tank as configured), written here so that this module never imports MuJoCo."""
    dry_mass, dry_inertia = cubesat.mass_properties(0.0)
    _, wet_inertia = cubesat.mass_properties(fuel_kg)
    return dry_mass * body.mass_scale + fuel_kg, dry_inertia * body.inertia_scale + (wet_inertia - dry_inertia)[:, None]


def step_rows(
    start: Motion,
    fuel_kg: np.ndarray,
    action: np.ndarray,
    frame: np.ndarray,
    body: StepBody,
    cubesat: CubeSatConfig,
    dt: float,
    substeps: int,
) -> tuple[Motion, np.ndarray]:
    """One control step of N bodies: ``start`` with ``fuel_kg`` (N,) in the tank, commanded
    ``action`` (N, 8) at ``frame`` (N,), through the record in ``body`` -> where they end and the
    fuel left (kg). The thrusts pass the fault and the fuel limit; the wrench acts about the
    centre of mass."""
    thrust = given_thrust(action, frame, body)
    burn = thrust.sum(axis=1) * cubesat.mass_flow_per_thrust * dt
    empties = burn > fuel_kg
    scale = np.where(empties, fuel_kg / np.where(empties, burn, 1.0), 1.0)  # the tank empties part-way
    thrust *= scale[:, None]
    mass, inertia = mass_and_inertia(cubesat, body, fuel_kg)
    W = _wrench(cubesat)  # about the cube's centre
    force = thrust @ W[:3].T  # N, body frame
    torque = thrust @ W[3:].T - cross(body.com, force)  # about the centre of mass
    end = fly(start, force / mass[:, None], torque, inertia, body, dt, substeps)
    return end, np.maximum(0.0, fuel_kg - burn * scale)


@lru_cache(maxsize=4)
def _wrench(cubesat: CubeSatConfig) -> np.ndarray:
    """The thrusters' wrench about the cube's centre (read-only: shared between calls)."""
    W = wrench_matrix(cubesat)
    W.flags.writeable = False
    return W
