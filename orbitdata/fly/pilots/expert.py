"""Expert level: OMPL RRT* around inflated obstacles, then PD tracking of a timed path."""

from __future__ import annotations

import numpy as np

from orbitdata.fly.pilot import Task
from orbitdata.fly.pilots.common import ControlledPilot, face, goal_seeking_accel, goal_seeking_velocity
from orbitdata.fly.pilots.config import ExpertConfig
from orbitdata.fly.pilots.planner import plan_path
from orbitdata.fly.pilots.trajectory import Trajectory, time_parametrise
from orbitdata.scenario.spec import Scenario
from orbitdata.seeding import rng as make_rng
from orbitdata.state import POSITION, so3_log

# m: when the look-ahead point is closer than this (the end of the path), look at the goal instead.
MIN_LOOK_DISTANCE = 0.2


class ExpertPilot(ControlledPilot):
    """Plans once at reset, then follows the path: the reference is the closest point of the
    timed path (so lagging never makes it chase a point far ahead), its speed-profile velocity
    and feed-forward acceleration. The camera looks ``lookahead`` metres down the path.
    If RRT* finds no path, the episode is flown goal-seeking and ``planner.solved`` is False.
    Privileged: it plans around the true obstacles of the scenario.

    ``plan_draw`` and ``noise_draw`` k > 0 give the k-th other draw of the task's RRT* plan and
    of its thrust noise (0: the episode's own, what the dataset records): other experts for the
    same task, for measuring how much of the expert's action its state does not determine.
    """

    name = "expert"
    privileged = True

    def __init__(self, config: ExpertConfig = ExpertConfig(), plan_draw: int = 0, noise_draw: int = 0, **kwargs):
        super().__init__(**kwargs)
        self.config = config
        self.plan_draw, self.noise_draw = int(plan_draw), int(noise_draw)

    def reset(self, task: Task, scenario: Scenario) -> None:
        cfg = self.config
        self.goal = np.asarray(task.goal, dtype=np.float64)
        self.rng = make_rng(task.seed, "pilot", self.noise_draw)
        inflation = self.controller.cubesat.bounding_radius + cfg.planner.margin
        v0 = float(np.linalg.norm(task.initial_velocity))
        plan = plan_path(
            (0.0, 0.0, 0.0),
            task.goal,
            scenario.obstacles,
            inflation,
            cfg.planner,
            make_rng(task.seed, "planner", self.plan_draw),
        )
        self.plan = plan
        self.trajectory: Trajectory | None = None
        if plan.solved:
            self.trajectory = time_parametrise(plan.path, v0, cfg.trajectory, scenario.obstacles, inflation)
        self._index = 0
        self._ahead = max(1, int(round(cfg.lookahead / cfg.trajectory.spacing)))
        self._cruise = max(cfg.trajectory.cruise_speed, v0)

    def rejoin(self, state: np.ndarray) -> int | None:
        """Take the path up again at its sample closest to ``state``'s position, searching the
        whole path rather than ahead of the last one (for states of another flight); returns the
        sample's index, or None without a path."""
        if self.trajectory is None:
            return None
        self._index = self._closest_anywhere(state[POSITION].astype(np.float64))
        return self._index

    def _closest_anywhere(self, p: np.ndarray) -> int:
        return int(np.argmin(np.sum((self.trajectory.points - p) ** 2, axis=1)))

    def deviation(self, state: np.ndarray) -> tuple[float, float, float] | None:
        """How far ``state`` is from flying this plan: (metres to the path, m/s from the velocity
        it would aim for there, degrees from the attitude it would command); None without a path.
        Past the path's end, where the expert flies goal-seeking, the velocity is goal-seeking's."""
        traj = self.trajectory
        if traj is None:
            return None
        p, v, R, *_ = self.controller.unpack(state)
        i = self._closest_anywhere(p)
        pos_ref, vel_ref, _ = traj.reference(i)
        look = traj.points[min(i + self._ahead, len(traj.points) - 1)] - p
        if i >= len(traj.points) - 1:
            vel_ref = goal_seeking_velocity(p, self.goal, self._cruise)
        if i >= len(traj.points) - 1 or np.linalg.norm(look) < MIN_LOOK_DISTANCE:
            look = self.goal - p
        turn = so3_log(R.T @ face(self.controller, state, look))
        return (
            float(np.linalg.norm(p - pos_ref)),
            float(np.linalg.norm(v - vel_ref)),
            float(np.degrees(np.linalg.norm(turn))),
        )

    def could_be_at(self, state: np.ndarray, position_m: float, speed_mps: float, angle_deg: float) -> bool:
        """Whether an expert flying this plan could be in ``state``: its :meth:`deviation` is
        within ``position_m``, ``speed_mps`` and ``angle_deg``."""
        d = self.deviation(state)
        return d is not None and d[0] <= position_m and d[1] <= speed_mps and d[2] <= angle_deg

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
        return {
            "planner": {
                "solved": p.solved,
                "iterations": p.iterations,
                "path_length": p.path_length,
                "planning_time": p.planning_time,
            }
        }
