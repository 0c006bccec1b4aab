"""What the built-in pilots share: a PD controller, goal-seeking flight and camera pointing."""

from __future__ import annotations

import numpy as np

from orbitdata.fly.pilot import Pilot
from orbitdata.fly.pilots.control import Controller, look_rotation


class ControlledPilot(Pilot):
    """A pilot that turns desired accelerations and attitudes into thrusts with a :class:`Controller`."""

    def __init__(self, controller: Controller | None = None):
        self.controller = controller or Controller()


# m/s added to the braking speed sqrt(2 a d), so that the approach never stalls short of the goal.
APPROACH_SPEED_FLOOR = 0.3


def goal_seeking_velocity(p: np.ndarray, goal: np.ndarray, cruise: float, brake_accel: float = 1.0) -> np.ndarray:
    """The velocity goal-seeking flight aims for at position ``p``: along the line of sight, slowing on arrival."""
    to_goal = goal - p
    dist = float(np.linalg.norm(to_goal))
    if dist < 1e-9:
        return np.zeros(3)
    return to_goal / dist * min(cruise, np.sqrt(2.0 * brake_accel * dist) + APPROACH_SPEED_FLOOR)


def goal_seeking_accel(
    controller: Controller, state: np.ndarray, goal: np.ndarray, cruise: float, brake_accel: float = 1.0
) -> np.ndarray:
    """PD towards the goal: aim for a velocity along the line of sight that slows on arrival."""
    p, *_ = controller.unpack(state)
    if np.linalg.norm(goal - p) < 1e-9:
        return controller.track_accel(state, goal, np.zeros(3))
    # Position error is along v_ref already; damp the velocity error only (pure pursuit).
    return controller.track_accel(state, p, goal_seeking_velocity(p, goal, cruise, brake_accel))


def face(controller: Controller, state: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The desired attitude (rotation matrix, body->world) that points the camera along ``direction``."""
    _, _, R, *_ = controller.unpack(state)
    if np.linalg.norm(direction) < 1e-6:
        return R
    return look_rotation(direction, fallback=R)
