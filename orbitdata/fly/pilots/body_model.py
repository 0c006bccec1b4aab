"""The CubeSat of one episode as the dynamic tier's expert models it, batched over candidates.

What it knows is the episode record (:class:`~orbitdata.scenario.dynamics.Dynamics`): the mass,
inertia and centre of mass as drawn, the faulty thruster and its onset, and the Clohessy-Wiltshire
terms when flagged. A static scene (no record) is the nominal body. Three pieces:

* :meth:`BodyModel.allocate`: body wrenches -> thrusts in [0, 1], knowing the fault. The nominal
  wrench matrix's null space is spanned by the even and by the odd thrusters (each set's thrusts
  cancel), so the exact solution with the least total thrust is the pseudo-inverse's plus the
  smallest shift of each set that makes it non-negative; a ``scaled`` thruster weighs its share
  of the shift by 1 / level. A dead (``off``) or ``stuck`` thruster leaves its set unable to
  shift and most wrenches out of reach: then the closest achievable wrench (bounded least squares),
  the stuck one's own wrench subtracted first.
* :meth:`BodyModel.command`: the attitude PD that turns the camera along the velocity (with a dead
  or stuck thruster, the intact ring along the acceleration first), plus a world-frame
  acceleration, as thrusts: the law that flies a plan, in its rollouts and for real.
* :meth:`BodyModel.rollout`: K acceleration sequences under the rigid-body dynamics (forces at the
  thrusters about the centre of mass, Euler's equations, semi-implicit steps of one or more
  control periods), the fault from its onset frame on, and the CW terms.

Frames as in :mod:`orbitdata.state`: p and v of the cube's centre in the world (Hill) frame,
R body -> world, w in the body frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitdata.fly.pilots.config import ControlGains
from orbitdata.scenario.dynamics import NO_FAULT, BodyParameters, Dynamics, ThrusterFault
from orbitdata.scenario.motion import cw_acceleration
from orbitdata.schema import ACTION_DIM, DT
from orbitdata.sim.config import CubeSatConfig
from orbitdata.sim.dynamic import body_mass_properties
from orbitdata.sim.thrusters import wrench_matrix

UP = np.array([0.0, 0.0, 1.0])  # the camera's image up stays near world +z, as the static expert's
# The hot loop runs on batches of a few dozen candidates, where each numpy call costs more than its
# arithmetic: products with these constants replace stacking, indexing and cross products.
_SKEW = np.zeros((3, 9))  # rotation vector (3,) @ _SKEW -> its skew matrix, flattened row-major
_SKEW[0, [7, 5]], _SKEW[1, [2, 6]], _SKEW[2, [3, 1]] = (1, -1), (1, -1), (1, -1)
_VEE_TRACE = np.zeros((9, 4))  # flattened M @ _VEE_TRACE -> [M21 - M12, M02 - M20, M10 - M01, trace M]
_VEE_TRACE[[7, 5], 0], _VEE_TRACE[[2, 6], 1], _VEE_TRACE[[3, 1], 2] = (1, -1), (1, -1), (1, -1)
_VEE_TRACE[[0, 4, 8], 3] = 1.0
_CYCLE1, _CYCLE2 = [1, 2, 0], [2, 0, 1]
TORQUE_WEIGHT = 3.0  # on the torque rows (per lever arm) of the fit with a dead or stuck thruster
VECTOR_ACCEL = 0.5  # m/s^2: below this a body with a dead or stuck thruster keeps its camera attitude
FIT_ITERATIONS = 12  # projected-gradient steps of the bounded least squares with a dead or stuck thruster


def _skew(c: np.ndarray) -> np.ndarray:
    """(3, 3) S with v @ S = v x c for row vectors v."""
    return (np.asarray(c, dtype=np.float64) @ _SKEW).reshape(3, 3)


def _norm(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.sum(x * x, axis=1))


def _exp(rotvec: np.ndarray) -> np.ndarray:
    """(K, 3) rotation vectors -> (K, 3, 3) rotations: I + sin(t)/t A + (1 - cos t)/t^2 A^2 (Rodrigues)."""
    theta = _norm(rotvec) + 1e-12
    A = (rotvec @ _SKEW).reshape(-1, 3, 3)
    half = np.sin(0.5 * theta) / (0.5 * theta)  # (1 - cos t) / t^2 = half^2 / 2
    return np.eye(3) + (np.sin(theta) / theta)[:, None, None] * A + (0.5 * half * half)[:, None, None] * (A @ A)


def _attitude_error(R: np.ndarray, R_des: np.ndarray) -> np.ndarray:
    """(K, 3) body-frame rotation vectors from R to R_des: log(R^T R_des), its size capped near pi."""
    vt = (R.transpose(0, 2, 1) @ R_des).reshape(-1, 9) @ _VEE_TRACE  # (K, 4)
    angle = np.arccos(np.clip(0.5 * (vt[:, 3] - 1.0), -1.0, 1.0)) + 1e-12
    return (0.5 / np.maximum(np.sin(angle) / angle, 0.05))[:, None] * vt[:, :3]


def look_rotations(forward: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(K, 3, 3) attitudes whose camera axis (body x) is along ``forward`` (K, 3) with body y level
    (image up near world +z); looking straight up or down, the level axis of R (K, 3, 3) is kept."""
    f = forward / _norm(forward)[:, None]
    r = np.hypot(f[:, 0], f[:, 1])  # the horizontal share of the camera axis
    if np.any(r < 1e-6):  # straight up or down: y from the current attitude
        y = np.where((r < 1e-6)[:, None], R[:, :, 1], np.stack([-f[:, 1], f[:, 0], np.zeros(len(f))], 1))
        y -= f * np.sum(f * y, axis=1, keepdims=True)
        y /= _norm(y)[:, None]
        return np.stack([f, y, np.cross(f, y)], axis=2)
    out = np.empty((len(f), 3, 3))
    out[:, :, 0] = f
    out[:, 0, 1], out[:, 1, 1], out[:, 2, 1] = -f[:, 1] / r, f[:, 0] / r, 0.0  # level: up x f
    out[:, 0, 2], out[:, 1, 2], out[:, 2, 2] = -f[:, 0] * f[:, 2] / r, -f[:, 1] * f[:, 2] / r, r  # f x y
    return out


@dataclass
class Rollout:
    """K candidates flown H steps: what the cost reads. Row h is the state after step h."""

    position: np.ndarray  # (K, H, 3) m, cube centre, world
    velocity: np.ndarray  # (K, H, 3) m/s, world, of the centre of mass
    camera: np.ndarray  # (K, H, 3) unit camera axis (body x) in the world
    thrust: np.ndarray  # (K, H) sum of the commanded normalised thrusts


class BodyModel:
    """The episode's body, thrusters and orbit as ``dynamics`` records them (None: the nominal body)."""

    def __init__(
        self,
        cubesat: CubeSatConfig = CubeSatConfig(),
        gains: ControlGains = ControlGains(),
        dynamics: Dynamics | None = None,
        look_bias: float = 0.3,
    ):
        self.cubesat, self.gains = cubesat, gains
        self.look_bias = look_bias  # m/s of goal direction added to the velocity the camera looks along
        self.body = dynamics.body if dynamics is not None else BodyParameters()
        self.fault = dynamics.fault if dynamics is not None else ThrusterFault()
        self.n = dynamics.n if dynamics is not None else 0.0  # rad/s, 0 without the CW terms
        self.com = np.asarray(self.body.com_offset, dtype=np.float64)  # m, body frame
        self.W = wrench_matrix(cubesat, self.com)  # (6, 8) about the centre of mass
        self._cross_com = _skew(self.com)  # w @ this = w x com
        self._nominal = self._allocation(self.W, np.ones(ACTION_DIM), (1.0, 1.0), np.zeros(6))
        self._faulty = self._nominal
        gain, offset = np.ones(ACTION_DIM), np.zeros(ACTION_DIM)  # what the thrusters give: gain * u + offset
        f = self.fault
        if f.kind != NO_FAULT:
            k = f.thruster
            W_eff, weight, shifts = self.W.copy(), np.ones(ACTION_DIM), [1.0, 1.0]
            if f.kind == "scaled" and f.level > 0:
                W_eff[:, k] *= f.level
                weight[k] = 1.0 / f.level  # the set still cancels with thruster k at 1 / level
            else:  # off, stuck (or scaled to nothing): k's command does nothing, and its set cannot cancel
                W_eff[:, k] = 0.0
                shifts[k % 2] = 0.0
            gain[k] = f.level if f.kind == "scaled" else 0.0
            offset[k] = f.level if f.kind == "stuck" else 0.0
            self._faulty = self._allocation(W_eff, weight, shifts, self.W @ offset)
        self._given = ((gain[:, None] * self.W.T), offset @ self.W.T)  # (8, 6), (6,)
        # A dead or stuck thruster leaves a quarter of the force directions at zero torque, so the
        # body turns its intact ring (+z for a dead thruster of the -z-pushing ring, and so on) to
        # where it must push, the camera as near its view as that allows.
        self.thrust_axis = 0.0
        if self._faulty[4] is not None:
            self.thrust_axis = -float(np.sign(self.W[2, f.thruster]))  # body z, +1 or -1

    def _allocation(self, W_eff: np.ndarray, weight: np.ndarray, shifts, bias: np.ndarray) -> tuple:
        """(pinv(W_eff)^T (6, 8), the sets' weights (4, 2), which sets may shift (2,), the thrusts
        (8,) that cancel the wrench ``bias`` the thrusters give whatever they are told, and, when a
        set cannot shift, the bounded least-squares problem that replaces the exact solution)."""
        pinv_t = np.linalg.pinv(W_eff).T
        pinv_t[:, ~W_eff.any(axis=0)] = 0.0  # a thruster that gives nothing is told nothing (not 1e-17)
        fit = None
        if not all(shifts):
            scale = np.array([1.0, 1.0, 1.0] + [TORQUE_WEIGHT / self.cubesat.half_size] * 3)
            M = scale[:, None] ** 2 * W_eff  # (6, 8): wrench @ M is the fit's linear term
            H = W_eff.T @ M  # (8, 8)
            fit = (M, bias @ M, H, float(np.linalg.eigvalsh(H).max()))
        return pinv_t, weight.reshape(4, 2), np.asarray(shifts), bias @ pinv_t, fit

    def mass_properties(self, fuel_ratio: float) -> tuple[float, np.ndarray]:
        """(mass kg, principal inertia (3,) kg m^2) with the tank at ``fuel_ratio``."""
        fuel_kg = float(np.clip(fuel_ratio, 0.0, 1.0)) * self.cubesat.fuel_mass
        return body_mass_properties(self.cubesat, self.body.mass_scale, self.body.inertia_scale, fuel_kg)

    def centre_of_mass(self, p: np.ndarray, v: np.ndarray, R: np.ndarray, w: np.ndarray):
        """(x, xv) (K, 3): the centre of mass's position and velocity (world) for the cube centre's."""
        return p + R @ self.com, v + np.einsum("kij,kj->ki", R, w @ self._cross_com)

    def allocate(self, wrench: np.ndarray, frame: int) -> np.ndarray:
        """(K, 6) body wrenches about the centre of mass -> (K, 8) commanded thrusts in [0, 1] for
        control step ``frame`` (the fault as it is then).

        With both sets able to shift, the exact least-thrust solution, scaled down when it needs
        more than full thrust. With a dead or stuck thruster most wrenches are out of reach (a
        quarter of the force directions remain at zero torque), so the thrusts are the closest
        achievable wrench: bounded least squares with the torque rows divided by the lever arm (as
        the static expert's allocator weighs them) and then weighted ``TORQUE_WEIGHT`` times, so
        that the body keeps its attitude; projected gradient with momentum from the clipped solution.
        """
        pinv_t, weight, shifts, bias, fit = self._faulty if self.fault.active(frame) else self._nominal
        u = (wrench @ pinv_t - bias).reshape(-1, 4, 2)  # the least-norm exact solution, signs mixed
        shift = np.maximum(np.max(-u / weight, axis=1), 0.0) * shifts  # (K, 2) per set
        u = np.maximum((u + shift[:, None, :] * weight).reshape(-1, ACTION_DIM), 0.0)
        if fit is None:
            return u / np.maximum(u.max(axis=1, keepdims=True), 1.0)
        M, bias_term, H, L = fit
        target = wrench @ M - bias_term  # (K, 8): minimise u H u / 2 - target u over the box
        u = np.minimum(u, 1.0)
        y, previous = u, u
        for i in range(FIT_ITERATIONS):
            u = np.minimum(np.maximum(y - (y @ H - target) / L, 0.0), 1.0)
            y, previous = u + (i / (i + 3.0)) * (u - previous), u
        return u

    def given(self, thrust: np.ndarray, frame: int) -> np.ndarray:
        """(K, 6) the body wrench the thrusters give for commands ``thrust`` (K, 8) at control step
        ``frame`` (the fault, once it has begun)."""
        if not self.fault.active(frame):
            return thrust @ self.W.T
        gain_wrench, offset_wrench = self._given
        return thrust @ gain_wrench + offset_wrench

    def command(self, x, xv, R, w, accel, goal, frame: int, mass: float, inertia: np.ndarray) -> np.ndarray:
        """(K, 8) thrusts for world accelerations ``accel`` (K, 3) m/s^2 at states (K, ...) of the
        centre of mass, while the camera turns along the velocity (with ``look_bias`` m/s towards
        the goal added, so that a slow body looks at it); with a dead or stuck thruster, the body's
        strong axis turns along the acceleration first (:meth:`vectored`)."""
        g = self.gains
        to_goal = goal - x
        look = xv + (self.look_bias / np.maximum(_norm(to_goal), 1e-9))[:, None] * to_goal
        R_des = look_rotations(look, R)
        if self.thrust_axis and self.fault.active(frame):
            R_des = self.vectored(R_des, accel)
        err = _attitude_error(R, R_des)
        alpha = g.att_kp * err - g.att_kd * w  # (K, 3) rad/s^2, body frame
        alpha *= np.minimum(1.0, g.max_alpha / np.maximum(_norm(alpha), 1e-12))[:, None]
        force = mass * np.einsum("kji,kj->ki", R, accel)  # (K, 3) N, body frame
        return self.allocate(np.concatenate([force, inertia * alpha], axis=1), frame)

    def vectored(self, R_look: np.ndarray, accel: np.ndarray) -> np.ndarray:
        """(K, 3, 3) attitudes whose body z (times ``thrust_axis``) points along ``accel`` (K, 3),
        blended towards ``R_look``'s below ``VECTOR_ACCEL``, with the camera axis nearest to
        ``R_look``'s."""
        z = self.thrust_axis * accel + VECTOR_ACCEL * R_look[:, :, 2]
        z /= np.maximum(_norm(z), 1e-12)[:, None]
        camera = R_look[:, :, 0]
        x = camera - z * np.sum(camera * z, axis=1, keepdims=True)
        x /= np.maximum(_norm(x), 1e-12)[:, None]  # camera along the thrust: a degenerate, passing instant
        y = z[:, _CYCLE1] * x[:, _CYCLE2] - z[:, _CYCLE2] * x[:, _CYCLE1]  # z x x
        return np.stack([x, y, z], axis=2)

    def rollout(
        self, state: tuple, accel: np.ndarray, goal: np.ndarray, frame: int, fuel_ratio: float, stride: int = 1
    ) -> Rollout:
        """Fly ``accel`` (K, H, 3) world accelerations, each held for ``stride`` control steps, from
        ``state`` = (p, v world, R, w body) of the cube's centre at control step ``frame``, commanding
        each step with :meth:`command`; row h of the result is ``(h + 1) * stride`` steps on."""
        K, H, _ = accel.shape
        dt = stride * DT  # s per rollout step
        mass, inertia = self.mass_properties(fuel_ratio)
        p, v, R, w = (np.repeat(np.asarray(a, dtype=np.float64)[None], K, axis=0) for a in state)
        x, xv = self.centre_of_mass(p, v, R, w)
        gyro = inertia[_CYCLE2] - inertia[_CYCLE1]  # w x (I w) = w[C1] w[C2] gyro for a diagonal I
        n = self.n
        out = Rollout(np.empty((K, H, 3)), np.empty((K, H, 3)), np.empty((K, H, 3)), np.empty((K, H)))
        for h in range(H):
            step = frame + h * stride
            u = self.command(x, xv, R, w, accel[:, h], goal, step, mass, inertia)
            wrench = self.given(u, step)  # (K, 6) body frame, about the centre of mass
            a = np.einsum("kij,kj->ki", R, wrench[:, :3]) / mass  # (K, 3) m/s^2, world
            if n:
                a += cw_acceleration(x, xv, n)
            # Euler's equations about the centre of mass, then the attitude over the step.
            w = w + (wrench[:, 3:] - w[:, _CYCLE1] * w[:, _CYCLE2] * gyro) / inertia * dt
            R = R @ _exp(w * dt)
            x = x + (xv + 0.5 * a * dt) * dt  # exact for the step's constant force
            xv = xv + a * dt
            out.position[:, h] = x - R @ self.com
            out.velocity[:, h], out.camera[:, h], out.thrust[:, h] = xv, R[:, :, 0], u.sum(axis=1)
        return out
