"""The planning pilots: MPPI on imagined futures, flown through the ``orbitdata.fly`` interface.

A pilot is reset with the task (goal, goal radius, initial velocity, seed) and then maps each
observation to 8 thrusts: it folds the frame into its model, replans with MPPI, executes the
first action of the plan. Which model of the dynamics and of the obstacles it plans with is
the :class:`Variant`:

==========================  ==================  ======================  ===========
variant                     dynamics            obstacles               privileged
==========================  ==================  ======================  ===========
planner                     world model+probe   depth head (16x16)      no
oracle-true                 rigid body          the scenario's          yes
oracle-learned-dyn          world model+probe   the scenario's          yes
oracle-true-dyn-depth       rigid body          depth head (16x16)      the body
oracle-true-dyn-sensor      rigid body          rendered depth_low      the body
==========================  ==================  ======================  ===========

The oracles that plan with the rigid body are handed the scenario (``reset(task, scenario=...)``)
for its body: on the dynamic tier that is the episode's own (``plan.true_body``: body, fault, CW
terms; ``PlannerConfig.body``), so ``oracle-true-dyn-depth`` and ``-sensor`` isolate what seeing
the debris through the camera costs. Only the privileged variants (the true obstacles) read the
scenario's obstacles; the planner is handed none of it.
``PlannerConfig.obstacle_motion`` says where each rollout step meets the obstacles (the step's
time is counted in control steps since the reset): still ("static"), carried by the tracker
("tracker", ``plan.tracker``), or for the oracles of a scenario whose debris moves, along their
exact motion ("true") or held where they are at the replan ("frozen"). The classes are
``orbitdata.fly.Pilot`` subclasses, so ``orbitdata fly --pilot planner --pilot-option run=RUN``
flies them too. Several episodes fly in lockstep with a :meth:`PlannerPilot.fork` each and
:meth:`PlannerPilot.act_batch` (``plan.batch``).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from orbitdata.fly import Pilot
from orbitdata.schema import DT
from orbitdata.seeding import rng
from orbitdata.sim.config import SimConfig
from orbitdata.sim.thrusters import wrench_matrix
from orbitmodel.kinematics import P
from orbitmodel.plan.batch import plan_batch
from orbitmodel.plan.config import HISTORY_BODIES, PlannerConfig
from orbitmodel.plan.imagined import ImaginedDepth, ImaginedField, outside_view
from orbitmodel.plan.mppi import MPPI
from orbitmodel.plan.obstacles import (
    Camera,
    PointCloud,
    PointMemory,
    TrueObstacles,
    border_points,
    depth_to_points,
)
from orbitmodel.plan.timing import Timings
from orbitmodel.plan.tracker import Tracker
from orbitmodel.plan.true_body import EpisodeBodyDynamics
from orbitmodel.plan.variant import Variant


def wrench_noise_basis(sim: SimConfig, torque_scale: float) -> torch.Tensor:
    """(8, 6) thrust patterns, each the least-squares way to make one body force or torque axis,
    normalised to unit length; the torque columns are scaled by ``torque_scale``."""
    W = wrench_matrix(sim.cubesat)  # (6, 8)
    B = np.linalg.pinv(W)  # (8, 6)
    B = B / np.linalg.norm(B, axis=0, keepdims=True)
    B[:, 3:] *= torque_scale
    return torch.tensor(B, dtype=torch.float32)


DepthSource = Callable[[dict], np.ndarray]  # observation -> (16, 16) z-depth, metres


@dataclass
class Replan:
    """What the pilot believed when it replanned at ``step`` (kept when ``record``)."""

    step: int
    path: np.ndarray  # (H, 3) metres, world: the cheapest candidate's imagined positions
    points: np.ndarray  # (N, 3) metres, world: the obstacle points it planned around
    cost: float


class PlannerPilot(Pilot):
    """MPPI on a dynamics model, around obstacles it sees. Never told where the obstacles are.

    Args:
        variant: which models (see the module docstring); a non-privileged one here.
        dynamics: ``RigidBodyDynamics`` or ``LearnedDynamics``.
        depth: observation -> 16x16 depth (the depth head, or the rendered ``depth_low``);
            None for the oracles that plan around the true obstacles.
        camera: the pinhole model that back-projects the depth map.
        config: see :class:`PlannerConfig`.
    """

    name = Variant.PLANNER.value
    privileged = False
    needs_images = True

    def __init__(
        self,
        variant: Variant,
        dynamics,
        depth: DepthSource | None,
        camera: Camera,
        config: PlannerConfig = PlannerConfig(),
        sim: SimConfig = SimConfig(),
        timings: Timings | None = None,
        imagined: ImaginedDepth | None = None,
    ):
        if variant.privileged != type(self).privileged:
            raise ValueError(f"variant {variant.value} needs {'OraclePilot' if variant.privileged else 'PlannerPilot'}")
        if (depth is None) != (variant.obstacles == "true"):
            raise ValueError(f"variant {variant.value}: give a depth source exactly when it plans around depth")
        motions = ("static", "true", "frozen") if variant.privileged else ("static", "tracker", "imagined")
        if config.obstacle_motion not in motions:
            raise ValueError(
                f"obstacle_motion={config.obstacle_motion}: pilot {variant.value} takes {', '.join(motions)}"
            )
        if config.body == "nominal" and variant.learned_dynamics:
            raise ValueError(
                f"body={config.body}: only the rigid-body oracles plan with a chosen body (oracle-true, "
                "oracle-true-dyn-depth, oracle-true-dyn-sensor); drop the body setting"
            )
        if config.body == "corrected" and not variant.learned_dynamics:
            raise ValueError(
                f"body=corrected corrects the world model's dynamics; pilot {variant.value} plans with the "
                "rigid-body model: fly planner or oracle-learned-dyn with it"
            )
        if config.body in HISTORY_BODIES and variant == Variant.ORACLE_LEARNED_DYN:
            raise ValueError(
                f"body={config.body}: oracle-learned-dyn plans with the learned dynamics; the true obstacles with "
                f"that body are oracle-true with body={config.body}"
            )
        self.variant, self.config, self.sim = variant, config, sim
        self.name = variant.value
        # A rigid-body oracle is handed the scenario, whose body it plans with (reset); never the planner.
        self.privileged = type(self).privileged or not variant.learned_dynamics
        self._rigid = dynamics  # the static tier's body, and what each episode's own is built beside
        self.needs_images = bool(dynamics.needs_images or depth is not None)
        self.image_codec = config.image_codec and self.needs_images
        self.sees_depth = variant.obstacles == "sensor"  # only the sensor oracle reads the rendered depth
        self.dynamics, self.depth, self.camera = dynamics, depth, camera
        self.timings = timings or getattr(dynamics, "timings", None) or Timings()
        basis = wrench_noise_basis(sim, config.torque_noise) if config.noise == "wrench" else None
        self.mppi = MPPI(config.mppi, noise_basis=basis)
        self.memory = PointMemory(config.memory_frames)
        self.tracker = Tracker(config.tracker) if config.obstacle_motion == "tracker" else None
        self.imagined = imagined
        if (imagined is not None) != (config.obstacle_motion == "imagined") or (
            imagined is not None and not getattr(dynamics, "reads_latent", False)
        ):
            raise ValueError(
                "obstacle_motion=imagined: give the imagined-depth head exactly then, to a planner whose "
                "dynamics imagine latents (a probe that reads them)"
            )
        self._true: TrueObstacles | None = None
        self.goal = torch.zeros(3)
        self.goal_radius = 0.5
        self._reset_episode(seed=0)

    # ---- the Pilot interface ----------------------------------------------------------------
    def reset(self, task, scenario=None) -> None:
        """Start an episode from an ``orbitdata.fly.Task`` (goal, goal_radius, seed, ...).

        ``scenario`` (the rigid-body oracles only; ``orbitdata.fly`` hands it to them): the episode's
        ground truth, whose body, fault and CW terms they plan with (``body="true"`` or "nominal");
        without it, the design's body. Its obstacles are read by :class:`OraclePilot` alone."""
        if scenario is not None and not self.privileged:
            raise ValueError(f"the {self.name} pilot is handed no ground truth: reset(task) without scenario")
        if not self.variant.learned_dynamics and self.config.body not in HISTORY_BODIES:
            if scenario is None or scenario.dynamics is None:
                self.dynamics = self._rigid
            else:
                self.dynamics = EpisodeBodyDynamics(
                    scenario.dynamics, self.sim, self.config.rigid_substeps, self.config.body == "nominal", self.timings
                )
        self.goal = torch.tensor(task.goal, dtype=torch.float32)
        self.goal_radius = float(task.goal_radius)
        self._reset_episode(int(task.seed))

    def act(self, obs: dict) -> np.ndarray:
        """(8,) thrusts in [0, 1]: replan (every ``replan_every`` steps), execute the first step."""
        return plan_batch([self], [obs])[0]

    @staticmethod
    def act_batch(pilots: list["PlannerPilot"], observations: list[dict]) -> list[np.ndarray]:
        """:meth:`act` for several episodes in lockstep, each flown by its own :meth:`fork`, with
        one call per model for all of them (``plan.batch``)."""
        return plan_batch(pilots, observations)

    @property
    def board_every(self) -> int:
        """Steps between replans: lockstep flights start episodes on this clock, so that the
        episodes in a batch replan at the same steps."""
        return self.config.replan_every

    def fork(self) -> "PlannerPilot":
        """A pilot for another episode flown beside this one: the same models, depth source,
        settings and timings; its own MPPI nominal, point memory, latent history and generator."""
        twin = copy.copy(self)
        twin.mppi = MPPI(self.config.mppi, noise_basis=self.mppi.basis)
        twin.memory = PointMemory(self.config.memory_frames)
        twin.tracker = None if self.tracker is None else Tracker(self.config.tracker)
        twin.dynamics = self.dynamics.fork()
        twin._true = None
        twin._reset_episode(seed=0)
        return twin

    def metadata(self) -> dict:
        """Per-episode facts: replans, effective samples, sanitised thrusts, latency."""
        steps = np.array(self.step_seconds) * 1e3
        replans = np.array(self.replan_seconds) * 1e3
        return {
            "variant": self.variant.value,
            "depth_source": getattr(self.depth, "name", self.variant.obstacles),  # stage1, refit, sensor, true
            "replans": len(replans),
            "nonfinite_actions": self.nonfinite_actions,
            "clipped_actions": self.clipped_actions,
            "step_ms_median": float(np.median(steps)) if len(steps) else None,
            "step_ms_p95": float(np.percentile(steps, 95)) if len(steps) else None,
            "replan_ms_median": float(np.median(replans)) if len(replans) else None,
            "replan_ms_p95": float(np.percentile(replans, 95)) if len(replans) else None,
            "effective_samples_median": float(np.median(self.effective_samples)) if self.effective_samples else None,
            "points_median": float(np.median(self.cloud_sizes)) if self.cloud_sizes else None,
        }

    # ---- internals --------------------------------------------------------------------------
    def _reset_episode(self, seed: int) -> None:
        # One torch generator per episode, from the episode seed's planner stream.
        self.generator = torch.Generator().manual_seed(int(rng(seed, "planner").integers(2**62)))
        self.mppi.reset()
        self.dynamics.reset()
        self.memory.reset()
        if self.tracker is not None:
            self.tracker.reset()
        self._previous: np.ndarray | None = None
        self._step = 0
        self.step_seconds: list[float] = []
        self.replan_seconds: list[float] = []
        self.effective_samples: list[float] = []
        self.cloud_sizes: list[int] = []
        self.nonfinite_actions = 0
        self.clipped_actions = 0
        self.replans: list[Replan] = []

    def _obstacles(self, obs: dict, depth: np.ndarray | None):
        """What to plan around: the true obstacles (oracles), else the memory of the points seen (or
        the tracker's moving clouds), with ``depth`` (16, 16) metres, this frame's map, added."""
        if self._true is not None:
            return self._true.now(self._step * DT)
        c = self.config
        with self.timings("points"):
            points, radii = depth_to_points(depth, obs["state"], self.camera, c.max_range, c.footprint, c.support)
            if self.tracker is None:
                self.memory.add(points, radii)
                cloud = self.memory.cloud(c.reach)
                if self.imagined is not None:  # what is in view now, the imagined maps replace
                    outside = outside_view(cloud.points, obs["state"], self.camera, c.max_range)
                    cloud = PointCloud(cloud.points[outside], cloud.radii[outside], c.reach)
            else:
                edge = border_points(depth, self.camera, c.max_range, c.support)
                self.tracker.add(points, radii, self._step * DT, edge)
                cloud = self.tracker.field(self._step * DT, c.reach)
        self.cloud_sizes.append(len(cloud))
        return cloud

    def plan_times(self) -> torch.Tensor | None:
        """(H,) seconds into the episode of the rollout's states (frames t+1..t+H of frame t, this
        step), for obstacles that move; None when the planner takes them to stand still."""
        if self.config.obstacle_motion in ("static", "imagined"):  # imagined maps carry their own time
            return None
        return (self._step + 1 + torch.arange(self.config.mppi.horizon, dtype=torch.float64)) * DT

    def round_field(self, field, states: torch.Tensor):
        """The field one MPPI round's candidates (``states`` (K, H, 16)) are costed against: ``field``,
        or with ``obstacle_motion="imagined"`` each candidate's imagined depth over it."""
        if self.imagined is None:
            return field
        with self.timings("imagined-depth"):
            maps = self.imagined.maps(self.dynamics.imagined_latents)  # (K, S, 16, 16) metres
            c = self.config
            return ImaginedField(maps, states, self.dynamics.step, self.camera, c.max_range, c.footprint, field)

    def _planned(self, result, field, states: torch.Tensor, seconds: float) -> None:
        """Keep what a replan found: its effective samples, its time, and with ``record`` the best
        candidate's imagined path (``states`` (K, H, 16) of the last round) and the points."""
        self.effective_samples.append(result.effective_samples)
        self.replan_seconds.append(seconds)
        if self.config.record:
            points = getattr(field, "points", np.zeros((0, 3)))
            path = states[result.best, :, P].numpy().copy()
            self.replans.append(Replan(self._step, path, np.asarray(points).copy(), float(result.costs[result.best])))

    def _execute(self) -> np.ndarray:
        """The plan's first step, made safe; the plan moves on by one step."""
        action = self._safe(self.mppi.nominal[0].numpy())
        self.mppi.shift()
        self._previous = action
        self._step += 1
        return action

    def _safe(self, action: np.ndarray) -> np.ndarray:
        """NaN / Inf -> 0 and out-of-range -> clipped, counted: nothing invalid reaches the simulator."""
        a = np.asarray(action, dtype=np.float64)
        bad = ~np.isfinite(a)
        if bad.any():
            self.nonfinite_actions += 1
            a = np.where(bad, 0.0, a)
        if a.min() < 0.0 or a.max() > 1.0:
            self.clipped_actions += 1
            a = np.clip(a, 0.0, 1.0)
        return a


class OraclePilot(PlannerPilot):
    """A planning pilot handed the true obstacles (privileged): the oracles of the grid. One that
    plans with the rigid body plans a dynamic-tier episode with that episode's body, fault and CW
    terms (``plan.true_body``; ``body="nominal"``: the design's body, no fault; ``body="fitted"``: the
    body fitted to its own history, ``plan.fitted_body``, which reads no record; ``body="inferred"``:
    that fit under a learned prior, ``plan.inferred_body``)."""

    privileged = True

    def reset(self, task, scenario=None) -> None:
        """``scenario``: the ground truth (orbitdata.fly passes it to privileged pilots only)."""
        if scenario is None:
            raise ValueError(f"the {self.name} oracle plans around the true obstacles: reset(task, scenario=...)")
        motion = self.config.obstacle_motion
        if motion == "static" and scenario.dynamics is not None:
            raise ValueError(
                f"the debris of this scenario moves: fly the {self.name} oracle with obstacle_motion=true "
                "(their exact motion) or obstacle_motion=frozen (held where they are at each replan)"
            )
        self._true = TrueObstacles(scenario, "true" if motion == "static" else motion)
        super().reset(task, scenario)
