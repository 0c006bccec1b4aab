"""CubeSatEnv: a free-floating 1U CubeSat with 8 thrusters among obstacles, in MuJoCo.

Spec (Gymnasium-style, version ``CubeSat-v1``):

* **Action**: 8 floats in [0, 1], normalised thrust of thrusters 0..7 (see
  :mod:`orbitdata.sim.thrusters` for the layout), held for one control step of 0.04 s.
  NaN/Inf, a wrong shape or values outside [0, 1] raise ``ValueError`` (no silent clipping).
* **Observation**: dict with ``state`` (16,) float32 [p, v_body, rot6d, w_body, fuel];
  and, when rendering, ``image`` (H, W, 3) uint8, ``depth`` (H, W) float32 metres along the
  optical axis (0 = no return within [near, far]) and ``depth_low`` (16, 16) float32 metres.
* **Episode end**: ``terminated`` at the first contact with an obstacle (``collision``),
  on entering the goal region (``success``) or with an empty tank (``out_of_fuel``);
  ``truncated`` when the frame index reaches ``max_steps - 1`` (``timeout``).
* **Reward**: +1 on success, -1 on collision, 0 otherwise (the dataset does not use it).
* **info**: ``outcome`` (None while flying), ``collision``, ``success``, ``contact_substep``,
  ``min_clearance`` (m, hull to nearest obstacle surface, 0 in contact), ``fuel_kg``,
  ``mass`` (kg), ``thrust`` (effective normalised thrust after fuel limits), ``position_world``,
  ``step``.
* **Arguments**: :class:`~orbitdata.sim.config.SimConfig` (physics, camera, hardware) and
  :class:`~orbitdata.scenario.config.ScenarioConfig` (randomisation).

Fuel: mass flow = sum(thrust) / (isp * g0); mass and inertia follow the tank; thrust stops
when it is empty (the last step is scaled to the fuel that was left).
"""

from __future__ import annotations

import mujoco
import numpy as np

from orbitdata.scenario.config import ScenarioConfig
from orbitdata.scenario.sampler import check_scenario, sample_scenario
from orbitdata.scenario.spec import Scenario
from orbitdata.schema import ACTION_DIM
from orbitdata.sim.config import SimConfig
from orbitdata.sim.mjcf import BODY, CAMERA, HULL, OBSTACLE_PREFIX, build_mjcf
from orbitdata.sim.render import CameraRenderer, pool_depth
from orbitdata.sim.thrusters import wrench_matrix
from orbitdata.state import make_state


def validate_action(action) -> np.ndarray:
    """Return ``action`` as float64 (8,) or raise ValueError saying what is wrong."""
    a = np.asarray(action, dtype=np.float64)
    if a.shape != (ACTION_DIM,):
        raise ValueError(f"action must have shape ({ACTION_DIM},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action contains NaN or Inf: {a.tolist()}")
    if a.min() < 0.0 or a.max() > 1.0:
        raise ValueError(
            f"action values must be in [0, 1] (normalised thrust), got min {a.min():.4g} max {a.max():.4g}"
        )
    return a


class CubeSatEnv:
    """The simulator. One instance owns one MuJoCo model and one offscreen GL context."""

    version = "CubeSat-v1"

    def __init__(self, sim: SimConfig = SimConfig(), scenario: ScenarioConfig = ScenarioConfig()):
        self.sim = sim
        self.scenario_config = scenario
        self.wrench_matrix = wrench_matrix(sim.cubesat)  # (6, 8) body frame
        sat = sim.cubesat
        self.body_radius = sat.bounding_radius  # m
        self._mdot_per_thrust = sat.mass_flow_per_thrust  # kg/s per unit thrust
        self._renderer: CameraRenderer | None = None
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self.scenario: Scenario | None = None

    # ---- lifecycle ------------------------------------------------------------------------
    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode. ``options``: ``scenario`` (a Scenario) or ``n_obstacles`` / ``speed``."""
        options = dict(options or {})
        scn = options.pop("scenario", None)
        if scn is None:
            if seed is None:
                raise ValueError("reset needs a seed (or options={'scenario': ...}); orbitdata has no global RNG")
            scn = sample_scenario(
                seed, self.scenario_config, options.pop("n_obstacles", None), options.pop("speed", None)
            )
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; expected scenario, n_obstacles, speed")
        check_scenario(scn, self.body_radius)
        self.scenario = scn
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(scn, self.sim))
        self.data = mujoco.MjData(self.model)
        self._scratch = mujoco.MjData(self.model)
        m, d = self.model, self.data
        self._body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, BODY)
        self._hull = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, HULL)
        self._obstacles = [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{OBSTACLE_PREFIX}{i}") for i in range(len(scn.obstacles))
        ]
        self._fuel = self.sim.cubesat.fuel_mass
        self._update_mass()
        d.qvel[0:3] = scn.initial_velocity  # free joint: linear velocity in the world frame
        mujoco.mj_forward(m, d)
        self._start = d.xpos[self._body].copy()
        self._goal = np.asarray(scn.goal, dtype=np.float64)
        self.t = 0
        self.done = False
        if self.sim.render:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = CameraRenderer(m, CAMERA, self.sim.camera, self.sim.gl_backend)
        clearance = self._min_clearance()
        obs = self._observe()
        info = self._info(None, False, False, None, clearance, np.zeros(ACTION_DIM))
        return obs, info

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ---- dynamics --------------------------------------------------------------------------
    def step(self, action):
        """Apply ``action`` for one control step. Returns (obs, reward, terminated, truncated, info)."""
        if self.data is None:
            raise RuntimeError("call reset() before step()")
        if self.done:
            raise RuntimeError("the episode has ended; call reset()")
        a = validate_action(action)
        m, d = self.model, self.data
        burn = float(a.sum()) * self._mdot_per_thrust * self.sim.dt  # kg this step
        if burn > self._fuel:
            a = a * (self._fuel / burn)  # the tank empties part-way: scale the whole step
            burn = self._fuel
        d.ctrl[:] = a
        contact_substep = None
        for k in range(self.sim.substeps):
            mujoco.mj_step(m, d)
            # mj_step collides the state it started from, so this sees substep k's start.
            if contact_substep is None and d.ncon and self._hull_in_contact():
                contact_substep = k
        # Recompute kinematics and contacts of the final state (mj_step leaves them stale).
        mujoco.mj_forward(m, d)
        if contact_substep is None and d.ncon and self._hull_in_contact():
            contact_substep = self.sim.substeps
        self._fuel = max(0.0, self._fuel - burn)
        self._update_mass()
        self.t += 1

        collision = contact_substep is not None
        success = (not collision) and bool(np.linalg.norm(d.xpos[self._body] - self._goal) <= self.scenario.goal_radius)
        outcome = None
        if collision:
            outcome = "collision"
        elif success:
            outcome = "success"
        elif self._fuel <= 0.0:
            outcome = "out_of_fuel"
        elif self.t >= self.sim.max_steps - 1:
            outcome = "timeout"
        terminated = outcome in ("collision", "success", "out_of_fuel")
        truncated = outcome == "timeout"
        self.done = terminated or truncated
        clearance = 0.0 if collision else self._min_clearance()
        reward = 1.0 if success else (-1.0 if collision else 0.0)
        return (
            self._observe(),
            reward,
            terminated,
            truncated,
            self._info(outcome, collision, success, contact_substep, clearance, a),
        )

    def _hull_in_contact(self) -> bool:
        d = self.data
        for i in range(d.ncon):
            c = d.contact[i]
            if self._hull in (c.geom1, c.geom2):
                return True
        return False

    def _update_mass(self) -> None:
        mass, inertia = self.sim.cubesat.mass_properties(self._fuel)
        self.model.body_mass[self._body] = mass
        self.model.body_inertia[self._body] = inertia
        # MuJoCo 4 caches mass-derived constants: refresh them (on scratch data, since
        # mj_setConst evaluates the model at qpos0).
        mujoco.mj_setConst(self.model, self._scratch)

    def _min_clearance(self) -> float:
        far = self.sim.camera.far
        best = far
        for g in self._obstacles:
            dist = mujoco.mj_geomDistance(self.model, self.data, self._hull, g, far, None)
            best = min(best, dist)
        return max(0.0, float(best))

    # ---- observation -----------------------------------------------------------------------
    @property
    def fuel_ratio(self) -> float:
        return self._fuel / self.sim.cubesat.fuel_mass

    @property
    def mass(self) -> float:
        return float(self.model.body_mass[self._body])

    def state(self) -> np.ndarray:
        d = self.data
        R = d.xmat[self._body].reshape(3, 3)
        v_body = R.T @ d.qvel[0:3]
        return make_state(d.xpos[self._body] - self._start, v_body, R, d.qvel[3:6], self.fuel_ratio)

    def _observe(self) -> dict:
        obs = {"state": self.state()}
        if self._renderer is not None:
            rgb, depth = self._renderer.render(self.data)
            obs["image"] = rgb
            obs["depth"] = depth
            obs["depth_low"] = pool_depth(depth, self._renderer.far)
        return obs

    def _info(self, outcome, collision, success, contact_substep, clearance, thrust) -> dict:
        return {
            "step": self.t,
            "outcome": outcome,
            "collision": collision,
            "success": success,
            "contact_substep": contact_substep,
            "min_clearance": clearance,
            "fuel_kg": self._fuel,
            "mass": self.mass,
            "thrust": np.asarray(thrust, dtype=np.float64),
            "position_world": self.data.xpos[self._body].copy(),
        }
