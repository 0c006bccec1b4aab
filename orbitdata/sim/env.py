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
  ``truncated`` when the frame index reaches ``max_steps - 1`` (``timeout``). On the dynamic
  tier also ``terminated`` when the body spins faster than ``DynamicConfig.max_body_rate``
  (``tumbling``).
* **Instability**: should MuJoCo still find the state numerically unstable (NaN, Inf or huge
  values) and reset it, ``step`` raises :class:`SimulationUnstable` and the episode is over: no
  frame is ever observed from a reset state.
* **Reward**: +1 on success, -1 on collision, 0 otherwise (the dataset does not use it).
* **info**: ``outcome`` (None while flying), ``collision``, ``success``, ``contact_substep``,
  ``min_clearance`` (m, hull to nearest obstacle surface, 0 in contact), ``fuel_kg``,
  ``mass`` (kg), ``thrust`` (the normalised thrust the thrusters gave: after a fault and the fuel
  limits), ``position_world``, ``step`` and ``obstacle_poses`` (N, 7): each obstacle's centre (m,
  world) and quat (w, x, y, z) at this frame. ``obstacle_poses`` is privileged: oracles and
  validation read it, a learned pilot never does (the observation carries no obstacle pose).
* **Arguments**: :class:`~orbitdata.sim.config.SimConfig` (physics, camera, hardware) and
  :class:`~orbitdata.scenario.config.ScenarioConfig` (randomisation; its ``tier``).

Fuel: mass flow = sum(thrust) / (isp * g0); mass and inertia follow the tank; thrust stops
when it is empty (the last step is scaled to the fuel that was left).

The dynamic tier (a scenario with ``dynamics``; :mod:`orbitdata.sim.dynamic`): obstacles are
mocap bodies moved each substep along their analytic motion; with the CW flag the
Clohessy-Wiltshire force acts on the CubeSat's centre of mass each substep; mass, inertia and
centre of mass are the drawn ones; the faulty thruster gives what the fault says from its onset
frame on (fuel follows what was given); RGB carries Gaussian noise and depth drops pixels (0),
while ``depth_low`` is pooled from the depth before dropout. The state's p and v stay those of
the cube's centre, where the camera and thrusters are fixed.
"""

from __future__ import annotations

import numbers

import mujoco
import numpy as np

from orbitdata.scenario.config import ScenarioConfig
from orbitdata.scenario.sampler import check_scenario, sample_scenario
from orbitdata.scenario.spec import Scenario
from orbitdata.schema import ACTION_DIM, TUMBLING
from orbitdata.sim.config import SimConfig
from orbitdata.sim.dynamic import DynamicWorld
from orbitdata.sim.mjcf import BODY, CAMERA, HULL, OBSTACLE_PREFIX, build_mjcf
from orbitdata.sim.render import CameraRenderer, pool_depth
from orbitdata.sim.thrusters import wrench_matrix
from orbitdata.state import make_state

# MuJoCo's warnings that it found the state unstable; on each it resets the state to the model's
# initial one and carries on, which an episode must never do silently.
INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)


class SimulationUnstable(RuntimeError):
    """MuJoCo found the state numerically unstable during a step and reset it: the episode ends
    with this error, since nothing after the reset belongs to the flight."""


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
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0):
            raise ValueError(f"seed={seed!r}: give a whole number >= 0")
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
        self._world = DynamicWorld(scn, self.sim, m, self._body) if scn.dynamics is not None else None
        self._static_poses = scn.obstacle_poses(0.0)[0] if self._world is None else None
        self._fuel = self.sim.cubesat.fuel_mass
        self._update_mass()
        self._warnings = {w: d.warning[w].number for w in INSTABILITY_WARNINGS}
        d.qvel[0:3] = scn.initial_velocity  # free joint: linear velocity in the world frame
        if self._world is not None:
            self._world.place_debris(d, 0)  # exactly, not as the MJCF's 9 digits put it
        mujoco.mj_forward(m, d)
        self._start = d.xpos[self._body].copy()
        self._goal = np.asarray(scn.goal, dtype=np.float64)
        self.t = 0
        self.done = False
        if self.sim.render:
            if self._world is not None and self._renderer is not None and self._renderer.can_render(m):
                self._renderer.rebind(m, CAMERA)  # the dynamic tier's textured context, kept
            else:
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
        world = self._world
        if world is not None:
            a = world.thrust(a, self.t)
        burn = float(a.sum()) * self._mdot_per_thrust * self.sim.dt  # kg this step
        if burn > self._fuel:
            a = a * (self._fuel / burn)  # the tank empties part-way: scale the whole step
            burn = self._fuel
        d.ctrl[:] = a
        rate_before = self.body_rate
        contact_substep = None
        for k in range(self.sim.substeps):
            if world is None:
                mujoco.mj_step(m, d)
            else:
                world.place_debris(d, self.t * self.sim.substeps + k)
                mujoco.mj_step1(m, d)  # positions and velocities of substep k's start ...
                if world.n:
                    world.apply_cw(m, d)  # ... give the CW force acting over it
                mujoco.mj_step2(m, d)
            # mj_step collides the state it started from, so this sees substep k's start.
            if contact_substep is None and d.ncon and self._hull_in_contact():
                contact_substep = k
        self._check_stable(rate_before)
        if world is not None:
            world.place_debris(d, (self.t + 1) * self.sim.substeps)
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
        elif world is not None and self.body_rate > self.scenario_config.dynamic.max_body_rate:
            outcome = TUMBLING
        elif self._fuel <= 0.0:
            outcome = "out_of_fuel"
        elif self.t >= self.sim.max_steps - 1:
            outcome = "timeout"
        terminated = outcome in ("collision", "success", "out_of_fuel", TUMBLING)
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

    def _check_stable(self, rate_before: float) -> None:
        """Raise :class:`SimulationUnstable` if MuJoCo reset the state during this step."""
        d = self.data
        for warning in INSTABILITY_WARNINGS:
            if d.warning[warning].number > self._warnings[warning]:
                self.done = True
                raise SimulationUnstable(
                    f"MuJoCo found the state unstable ({warning.name}) in the step from frame {self.t} of the "
                    f"episode with seed {self.scenario.seed} (body rate {rate_before:.4g} rad/s before it) and "
                    "reset it; the episode cannot go on from a reset state. On the dynamic tier "
                    "scenario.dynamic.max_body_rate ends a spinning flight before this; lower it, or "
                    "keep the pilot from spinning the body up"
                )

    def _hull_in_contact(self) -> bool:
        d = self.data
        for i in range(d.ncon):
            c = d.contact[i]
            if self._hull in (c.geom1, c.geom2):
                return True
        return False

    def _update_mass(self) -> None:
        if self._world is None:
            mass, inertia = self.sim.cubesat.mass_properties(self._fuel)
        else:
            mass, inertia = self._world.mass_properties(self._fuel)
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

    @property
    def body_rate(self) -> float:
        """rad/s, the magnitude of the body's angular velocity."""
        return float(np.linalg.norm(self.data.qvel[3:6]))

    def state(self) -> np.ndarray:
        d = self.data
        R = d.xmat[self._body].reshape(3, 3)
        v_body = R.T @ d.qvel[0:3]
        return make_state(d.xpos[self._body] - self._start, v_body, R, d.qvel[3:6], self.fuel_ratio)

    def _observe(self) -> dict:
        obs = {"state": self.state()}
        if self._renderer is not None:
            rgb, depth = self._renderer.render(self.data)
            depth_low = pool_depth(depth, self._renderer.far)  # before dropout: the scene's depth
            if self._world is not None:
                rgb, depth = self._world.sense(rgb, depth, self.t)
            obs["image"] = rgb
            obs["depth"] = depth
            obs["depth_low"] = depth_low
        return obs

    def obstacle_poses(self) -> np.ndarray:
        """(N, 7) privileged: each obstacle's centre (m, world) and quat (w, x, y, z) now."""
        if self._world is None:
            return self._static_poses.copy()
        return self._world.poses(self.t)

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
            "obstacle_poses": self.obstacle_poses(),
        }
