"""Expert level: OMPL RRT* around inflated obstacles, then PD tracking of a timed path."""

from __future__ import annotations

import numpy as np

from orbitdata.fly.pilot import Task
from orbitdata.fly.pilots.common import ControlledPilot, face, goal_seeking_accel
from orbitdata.fly.pilots.config import ExpertConfig
from orbitdata.fly.pilots.planner import plan_path
from orbitdata.fly.pilots.trajectory import Trajectory, time_parametrise
from orbitdata.scenario.spec import Scenario
from orbitdata.seeding import rng as make_rng
from orbitdata.state import POSITION

# m: when the look-ahead point is closer than this (the end of the path), look at the goal instead.
MIN_LOOK_DISTANCE = 0.2


class ExpertPilot(ControlledPilot):
    """Plans once at reset, then follows the path: the reference is the closest point of the
    timed path (so lagging never makes it chase a point far ahead), its speed-profile velocity
    and feed-forward acceleration. The camera looks ``lookahead`` metres down the path.
    If RRT* finds no path, the episode is flown goal-seeking and ``planner.solved`` is False.
    Privileged: it plans around the true obstacles of the scenario.
    """

    name = "expert"
    privileged = True

    def __init__(self, config: ExpertConfig = ExpertConfig(), **kwargs):
        super().__init__(**kwargs)
        self.config = config

    def reset(self, task: Task, scenario: Scenario) -> None:
        cfg = self.config
        self.goal = np.asarray(task.goal, dtype=np.float64)
        self.rng = make_rng(task.seed, "pilot")
        inflation = self.controller.cubesat.bounding_radius + cfg.planner.margin
        v0 = float(np.linalg.norm(task.initial_velocity))
        plan = plan_path((0.0, 0.0, 0.0), task.goal, scenario.obstacles, inflation, cfg.planner,
                         make_rng(task.seed, "planner"))
        self.plan = plan
        self.trajectory: Trajectory | None = None
        if plan.solved:
            self.trajectory = time_parametrise(plan.path, v0, cfg.trajectory, scenario.obstacles, inflation)
        self._index = 0
        self._ahead = max(1, int(round(cfg.lookahead / cfg.trajectory.spacing)))
        self._cruise = max(cfg.trajectory.cruise_speed, v0)

    def act(self, obs: dict) -> np.ndarray:
        state = obs["state"]
        traj = self.trajectory
        p = state[POSITION].astype(np.float64)
        if traj is None or self._index >= len(traj.points) - 1:
            accel = goal_seeking_accel(self.controller, state, self.goal, self._cruise)
            look = self.goal - p
        else:
            self._index = traj.closest(p, hint=self._index)
            pos_ref, vel_ref, acc_ref = traj.reference(self._index)
            accel = self.controller.track_accel(state, pos_ref, vel_ref, acc_ref)
            look = traj.points[min(self._index + self._ahead, len(traj.points) - 1)] - p
            if np.linalg.norm(look) < MIN_LOOK_DISTANCE:
                look = self.goal - p
        thrust = self.controller.thrust(state, accel, face(self.controller, state, look))
        noise = self.rng.normal(0.0, self.config.noise_std, thrust.shape)
        return np.clip(thrust + noise, 0.0, 1.0)

    def metadata(self) -> dict:
        p = self.plan
        return {"planner": {"solved": p.solved, "iterations": p.iterations, "path_length": p.path_length,
                            "planning_time": p.planning_time}}
