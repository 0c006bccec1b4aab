"""The dynamic tier's residuals: how far each recorded step lies from the simulator's integrator.

:func:`thrust_residuals` compares the velocities, angular velocities and fuel that the recorded
thrust gives (:func:`orbitdata.sim.rigid_body.step_rows`) with those recorded at the step's end.
:func:`pose_residuals` is the kinematic check of this tier: it finds the constant body wrench that
carries the recorded velocities of a step's start to those of its end, and compares the pose it
flies with the recorded one, so that it reads no thrust record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitdata.sim.config import CubeSatConfig
from orbitdata.sim.rigid_body import StepBody, cross, fly, mass_and_inertia, rows, start_of, step_rows
from orbitdata.state import ANGULAR_VELOCITY, FUEL, POSITION, ROT6D, VELOCITY, rot6d_to_matrix

WRENCH_ITERATIONS = 4  # fixed-point steps of the wrench that :func:`pose_residuals` infers


@dataclass
class ThrustResiduals:
    velocity: np.ndarray  # (N,) m/s, world frame
    angular_velocity: np.ndarray  # (N,) rad/s, body frame
    fuel: np.ndarray  # (N,) fuel ratio


def thrust_residuals(
    s0: np.ndarray,
    s1: np.ndarray,
    action: np.ndarray,
    frame: np.ndarray,
    body: StepBody,
    cubesat: CubeSatConfig,
    dt: float,
    substeps: int,
) -> ThrustResiduals:
    """How far the recorded end of each step s0 -> s1 (states (N, 16) float64) lies from where the
    commanded ``action`` (N, 8), through the record in ``body``, takes s0."""
    fuel = s0[:, FUEL.start] * cubesat.fuel_mass  # kg at the step's start
    end, fuel_left = step_rows(start_of(s0), fuel, action, frame, body, cubesat, dt, substeps)
    R1 = rot6d_to_matrix(s1[:, ROT6D])
    return ThrustResiduals(
        np.linalg.norm(end.v - rows(R1, s1[:, VELOCITY]), axis=1),
        np.linalg.norm(end.w - s1[:, ANGULAR_VELOCITY], axis=1),
        np.abs(fuel_left / cubesat.fuel_mass - s1[:, FUEL.start]),
    )


def pose_residuals(
    s0: np.ndarray, s1: np.ndarray, body: StepBody, cubesat: CubeSatConfig, dt: float, substeps: int
) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and attitude (rad) residuals of steps s0 -> s1 under the body in ``body``, with
    the constant body-frame force and torque that carry s0's velocities to s1's (no thrust read)."""
    start = start_of(s0)
    R1 = rot6d_to_matrix(s1[:, ROT6D])
    v1, w1 = rows(R1, s1[:, VELOCITY]), s1[:, ANGULAR_VELOCITY]
    _, inertia = mass_and_inertia(cubesat, body, s0[:, FUEL.start] * cubesat.fuel_mass)
    force = np.einsum("nji,nj->ni", start.R, v1 - start.v) / dt  # per unit mass, body frame
    torque = inertia * (w1 - start.w) / dt + cross(start.w, inertia * start.w)
    for _ in range(WRENCH_ITERATIONS):
        end = fly(start, force, torque, inertia, body, dt, substeps)
        force = force + np.linalg.solve(end.turn, (v1 - end.v)[:, :, None])[:, :, 0]
        torque = torque + inertia * (w1 - end.w) / dt
    end = fly(start, force, torque, inertia, body, dt, substeps)
    cos = (np.einsum("nij,nij->n", end.R, R1) - 1.0) / 2.0
    return np.linalg.norm(end.p - s1[:, POSITION], axis=1), np.arccos(np.clip(cos, -1.0, 1.0))
