"""The simulator's side of the dynamic tier: debris moved along its analytic motion, the
Clohessy-Wiltshire terms, the body as drawn, the faulty thruster and the camera's noise.

:class:`CubeSatEnv` holds one :class:`DynamicWorld` per dynamic-tier episode and calls it at the
points where the tier differs from the static scenes; a static episode never builds one.
"""

from __future__ import annotations

import mujoco
import numpy as np

from orbitdata.scenario.motion import cw_acceleration
from orbitdata.scenario.spec import Scenario
from orbitdata.seeding import rng as make_rng
from orbitdata.sim.config import CubeSatConfig, SimConfig
from orbitdata.sim.mjcf import DEBRIS_PREFIX
from orbitdata.state import cross3


def body_mass_properties(cubesat: CubeSatConfig, mass_scale: float, inertia_scale, fuel_kg: float):
    """(mass kg, principal inertia (3,) kg m^2) of the drawn body with ``fuel_kg`` in the tank:
    the dry mass and each dry principal inertia scaled, the tank as configured."""
    dry_mass, dry_inertia = cubesat.mass_properties(0.0)
    _, wet_inertia = cubesat.mass_properties(fuel_kg)
    tank = wet_inertia - dry_inertia  # the tank's share, isotropic
    return dry_mass * mass_scale + fuel_kg, dry_inertia * np.asarray(inertia_scale, dtype=np.float64) + tank


def sense(rgb: np.ndarray, depth: np.ndarray, seed: int, frame: int, rgb_noise: float, dropout: float):
    """The camera's noisy view of frame ``frame``: Gaussian noise of ``rgb_noise`` (in [0, 1] units)
    on RGB, rounded and clipped to uint8, and a share ``dropout`` of depth pixels with no return (0).

    A pure function of (episode seed, frame): each frame draws from its own generator, so a
    validator can redraw any frame's noise and dropout mask alone.
    """
    g = make_rng(seed, "sensor-noise", draw=frame + 1)
    noise = g.standard_normal(rgb.shape, dtype=np.float32) * np.float32(255.0 * rgb_noise)
    noisy = np.clip(np.rint(rgb.astype(np.float32) + noise), 0, 255).astype(np.uint8)
    dropped = g.random(depth.shape, dtype=np.float32) < np.float32(dropout)
    return noisy, np.where(dropped, np.float32(0.0), depth)


class DynamicWorld:
    """One dynamic-tier episode in one MuJoCo model (built by :func:`~orbitdata.sim.mjcf.build_mjcf`).

    Debris poses are computed once for every physics substep of the episode (the analytic motion
    at time k * dt / substeps), so the mocap bodies sit exactly where the record says.
    """

    def __init__(self, scn: Scenario, sim: SimConfig, model: mujoco.MjModel, body: int):
        dyn = scn.dynamics
        assert dyn is not None, "a DynamicWorld needs a dynamic-tier scenario"
        self.scenario, self.dynamics, self.sim = scn, dyn, sim
        self.fault, self.n = dyn.fault, dyn.n
        self._body = body
        self._com = np.asarray(dyn.body.com_offset, dtype=np.float64)  # m, body frame
        substeps = sim.substeps
        times = np.arange(sim.max_steps * substeps + 1) / substeps * sim.dt  # s; frame t at t * dt exactly
        self._poses = scn.obstacle_poses(times)  # (K, N, 7) centre and quat per substep
        self._mocap = [
            int(model.body_mocapid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{DEBRIS_PREFIX}{i}")])
            for i in range(len(scn.obstacles))
        ]

    def mass_properties(self, fuel_kg: float):
        body = self.dynamics.body
        return body_mass_properties(self.sim.cubesat, body.mass_scale, body.inertia_scale, fuel_kg)

    def thrust(self, command: np.ndarray, step: int) -> np.ndarray:
        """What the thrusters give at frame ``step`` for ``command`` (the fault, if it has begun)."""
        return self.fault.apply(command, step)

    def place_debris(self, data: mujoco.MjData, substep: int) -> None:
        """Put every piece where it is ``substep`` physics steps into the episode."""
        poses = self._poses[substep]
        for i, mocap in enumerate(self._mocap):
            data.mocap_pos[mocap] = poses[i, :3]
            data.mocap_quat[mocap] = poses[i, 3:]

    def poses(self, frame: int, substep: int = 0) -> np.ndarray:
        """(N, 7) debris poses at frame ``frame``: centre (m, world) and quat (w, x, y, z)."""
        return self._poses[frame * self.sim.substeps + substep].copy()

    def apply_cw(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Set the Clohessy-Wiltshire force on the centre of mass from the state that ``mj_step1``
        has just evaluated (``xipos``, ``xmat`` and ``qvel`` of the same instant)."""
        b = self._body
        R = data.xmat[b].reshape(3, 3)
        omega = R @ data.qvel[3:6]  # rad/s, world frame (a free joint's is in the body frame)
        v_com = data.qvel[0:3] + cross3(omega, data.xipos[b] - data.xpos[b])
        data.xfrc_applied[b, 0:3] = model.body_mass[b] * cw_acceleration(data.xipos[b], v_com, self.n)

    def sense(self, rgb: np.ndarray, depth: np.ndarray, frame: int):
        s = self.dynamics.sensing
        return sense(rgb, depth, self.scenario.seed, frame, s.rgb_noise, s.depth_dropout)

    def com_world(self, data: mujoco.MjData) -> np.ndarray:
        """m, the centre of mass in the world frame."""
        return data.xpos[self._body] + data.xmat[self._body].reshape(3, 3) @ self._com
