"""The dynamic tier's expert: MPPI (Williams et al. 2017) with the episode's true dynamics, scored
against the debris where it will be.

Privileged like the static expert, it reads the episode record: the debris' motion, the body's
mass, inertia and centre of mass, the faulty thruster and its onset, and the CW flag. Every few
control steps it replans::

    A_k = cap(U + eps_k)                      K acceleration sequences (H, 3), world frame
    rollout_k = fly A_k with BodyModel        thrusts by the PD + allocation that knows the fault,
                                              rigid body about the true centre of mass, CW terms
    c_k = sum_h cost(rollout_k[h], debris where it is then) + terminal
    U <- sum_k softmax(-(c - min c) / lambda)_k A_k

The candidates are the last plan shifted by the steps flown since (the warm start), a fan of
velocity changes (faster, slower, a stop, and turns of 35 and 70 degrees in six directions round
the line of sight), and random perturbations of the last plan, smooth between knots. Why not raw
thrust sequences: the body turns a thousand times faster than it travels (5 N at the corners of
a 1.4 kg, 10 cm cube), so open-loop thrusts over a horizon tumble it; each candidate's thrust
sequence is instead what the attitude PD and the allocation command along its rollout, and the
executed thrust is that law's at the real state with the plan's acceleration. The camera looks
along the velocity, as the static expert looks down its path. Between replans the plan is flown
as it stands; while its best candidate passes within the margin of debris, replans come sooner.
"""

from __future__ import annotations

import math
import time

import numpy as np

from orbitdata.fly.pilot import Pilot, Task
from orbitdata.fly.pilots.body_model import BodyModel, Rollout
from orbitdata.fly.pilots.config import ControlGains, DynamicExpertConfig
from orbitdata.fly.pilots.debris_field import DebrisField
from orbitdata.scenario.spec import Scenario
from orbitdata.schema import DT
from orbitdata.seeding import rng as make_rng
from orbitdata.sim.config import CubeSatConfig
from orbitdata.state import ANGULAR_VELOCITY, FUEL, POSITION, ROT6D, VELOCITY, rot6d_to_matrix

GOAL_MARGIN = 0.05  # m inside the goal region that a rollout must reach to count as arrived
TURNS_DEG = (35.0, 70.0)  # the fan's turns away from the line of sight
TURN_DIRECTIONS = 6  # directions round the line of sight
SPEED_FACTORS = (0.5, 1.0, 1.5)  # the fan's speeds along the line of sight, times the cruise
VELOCITY_TIME = 0.5  # s over which a fan candidate changes its velocity (within max_accel)


def _knots(horizon: int, every: float) -> np.ndarray:
    """(H, n) linear interpolation from knots every ``every`` steps to the horizon's steps."""
    n = math.ceil((horizon - 1) / every) + 1
    h = np.arange(horizon) / every
    return np.maximum(0.0, 1.0 - np.abs(h[:, None] - np.arange(n)[None, :]))


def _cap(accel: np.ndarray, limit: float) -> np.ndarray:
    norm = np.linalg.norm(accel, axis=-1, keepdims=True)
    return accel * np.minimum(1.0, limit / np.maximum(norm, 1e-12))


class DynamicExpertPilot(Pilot):
    """MPPI over the true dynamics of the episode (its ``Scenario.dynamics``); see the module.

    ``plan_draw`` and ``noise_draw`` k > 0 give the k-th other draw of the sampling and of the
    thrust noise (0: the episode's own), as the static expert's. ``max_steps``: the episode's frame
    limit, over which the debris' poses are taken.
    """

    name = "expert"
    privileged = True

    def __init__(
        self,
        config: DynamicExpertConfig = DynamicExpertConfig(),
        cubesat: CubeSatConfig = CubeSatConfig(),
        gains: ControlGains = ControlGains(),
        max_steps: int = 300,
        plan_draw: int = 0,
        noise_draw: int = 0,
    ):
        self.config, self.cubesat, self.gains = config, cubesat, gains
        self.max_steps = max_steps
        self.plan_draw, self.noise_draw = int(plan_draw), int(noise_draw)
        self._steps = math.ceil(config.horizon / config.stride)  # H rollout steps of ``stride`` control steps
        self._interp = _knots(self._steps, config.knot_every / config.stride)  # (H, n)

    def reset(self, task: Task, scenario: Scenario) -> None:
        cfg = self.config
        self.model = BodyModel(self.cubesat, self.gains, scenario.dynamics, cfg.look_bias)
        self.debris = DebrisField(scenario, self.max_steps + cfg.horizon + 1)
        self.goal = np.asarray(task.goal, dtype=np.float64)
        self.goal_radius = float(task.goal_radius)
        self.cruise = max(cfg.cruise, float(np.linalg.norm(task.initial_velocity)))
        self.sampling = make_rng(task.seed, "planner", self.plan_draw)
        self.noise = make_rng(task.seed, "pilot", self.noise_draw)
        self.plan = np.zeros((self._steps * cfg.stride, 3))  # m/s^2 world, per control step from plan_start on
        self.plan_start = 0
        self.t = 0  # the control step about to be commanded
        self._next_replan = 0
        self.replans, self.planning_time, self.blocked = 0, 0.0, 0

    # ---- flying ----------------------------------------------------------------------------------
    def act(self, obs: dict) -> np.ndarray:
        s = obs["state"].astype(np.float64)
        R = rot6d_to_matrix(s[ROT6D])
        state = (s[POSITION], R @ s[VELOCITY], R, s[ANGULAR_VELOCITY])
        fuel = float(s[FUEL.start])
        if self.t >= self._next_replan:
            self._replan(state, fuel)
        j = self.t - self.plan_start
        accel = self.plan[j] if j < len(self.plan) else np.zeros(3)
        mass, inertia = self.model.mass_properties(fuel)
        p, v, R, w = (x[None] for x in state)
        thrust = self.model.command(
            *self.model.centre_of_mass(p, v, R, w), R, w, accel[None], self.goal, self.t, mass, inertia
        )[0]
        self.t += 1
        noise = self.noise.normal(0.0, self.config.noise_std, thrust.shape)
        return np.clip(thrust + noise, 0.0, 1.0)

    def _replan(self, state: tuple, fuel: float) -> None:
        cfg = self.config
        t0 = time.perf_counter()
        shift = min(self.t - self.plan_start, len(self.plan))
        warm = np.concatenate([self.plan[shift:], np.zeros((shift, 3))])[:: cfg.stride]  # (H, 3)
        fan = self._fan(state[0], state[1])
        n_random = max(cfg.samples - 1 - len(fan), 0)
        knots = self.sampling.normal(0.0, cfg.sample_std, (n_random, self._interp.shape[1], 3))
        perturbed = warm[None] + np.einsum("hn,knd->khd", self._interp, knots)
        candidates = _cap(np.concatenate([warm[None], fan, perturbed])[: max(cfg.samples, 2)], cfg.max_accel)
        rollout = self.model.rollout(state, candidates, self.goal, self.t, fuel, cfg.stride)
        cost, closest = self._cost(rollout)
        weights = np.exp(-(cost - cost.min()) / cfg.temperature)
        self.plan = np.repeat(np.einsum("k,khd->hd", weights / weights.sum(), candidates), cfg.stride, axis=0)
        self.plan_start = self.t
        best = closest[int(np.argmin(cost))]
        self.blocked += int(best < cfg.contact)
        self._next_replan = self.t + (cfg.replan_near if best < cfg.margin else cfg.replan_every)
        self.replans += 1
        self.planning_time += time.perf_counter() - t0

    def _fan(self, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(M, H, 3) accelerations that change the velocity to each of the fan's and then hold it."""
        cfg = self.config
        to_goal = self.goal - p
        ahead = to_goal / max(float(np.linalg.norm(to_goal)), 1e-9)
        helper = np.array([0.0, 0.0, 1.0]) if abs(ahead[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(ahead, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(ahead, e1)
        targets = [f * self.cruise * ahead for f in SPEED_FACTORS] + [np.zeros(3)]
        for turn in np.radians(TURNS_DEG):
            for phi in np.arange(TURN_DIRECTIONS) * 2 * np.pi / TURN_DIRECTIONS:
                side = np.cos(phi) * e1 + np.sin(phi) * e2
                targets.append(self.cruise * (np.cos(turn) * ahead + np.sin(turn) * side))
        change = np.array(targets) - v  # (M, 3) m/s
        dt = cfg.stride * DT  # s per rollout step
        steps = np.maximum(np.ceil(np.linalg.norm(change, axis=1) / (cfg.max_accel * dt)), round(VELOCITY_TIME / dt))
        h = np.arange(self._steps)
        return np.where(h[None, :, None] < steps[:, None, None], (change / (steps * dt)[:, None])[:, None], 0.0)

    def _cost(self, r: Rollout) -> tuple[np.ndarray, np.ndarray]:
        """(K,) costs of the rollouts and (K,) their closest hull clearance (m) before arriving."""
        cfg = self.config
        H = r.position.shape[1]
        distance = np.linalg.norm(r.position - self.goal, axis=2)  # (K, H) m
        arrived = np.logical_or.accumulate(distance <= self.goal_radius - GOAL_MARGIN, axis=1)
        flying = np.concatenate([np.ones((len(distance), 1), bool), ~arrived[:, :-1]], axis=1)  # (K, H)
        clear = self.debris.clearance(r.position, self.t + cfg.stride, cfg.stride) - self.cubesat.bounding_radius
        hit = (clear < cfg.contact) & flying
        speed = np.linalg.norm(r.velocity, axis=2)
        facing = np.sum(r.camera * r.velocity, axis=2) / np.maximum(speed, 1e-9)
        step = (
            cfg.goal * distance
            + cfg.clearance * np.maximum(cfg.margin - clear, 0.0) ** 2
            + cfg.effort * r.thrust
            + cfg.attitude * np.where(speed > 0.3, 1.0 - facing, 0.0)
            + cfg.speed * np.maximum(speed - cfg.max_speed, 0.0) ** 2
        )
        # Per control step: a rollout step stands for ``stride`` of them.
        cost = cfg.stride * np.sum(np.where(flying, step, 0.0), axis=1)
        cost += cfg.terminal * np.where(arrived[:, -1], 0.0, distance[:, -1])
        first_hit = np.argmax(hit, axis=1)
        cost += cfg.collision * hit.any(axis=1) * (2.0 - first_hit / H)
        closest = np.min(np.where(flying, clear, np.inf), axis=1)
        return cost, closest

    def metadata(self) -> dict:
        """``solved``: every replan found a candidate predicted clear of the debris; ``iterations``:
        the replans (each one batch of K rollouts); ``blocked``: replans that found none."""
        return {
            "planner": {
                "solved": self.blocked == 0,
                "iterations": self.replans,
                "blocked": self.blocked,
                "planning_time": self.planning_time,
            }
        }
