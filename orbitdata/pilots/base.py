"""The pilot interface shared by the expert, risky and exploratory levels."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from orbitdata.scenario.spec import Scenario
from orbitdata.pilots.control import Controller, look_rotation


class Pilot(ABC):
    """Flies one episode at a time. ``reset`` sees the scenario (a pilot may plan with it);
    ``act`` maps the 16-float state to 8 thrusts in [0, 1]. All randomness comes from the
    seed given to ``reset``."""

    level: str = ""

    def __init__(self, controller: Controller | None = None):
        self.controller = controller or Controller()

    @abstractmethod
    def reset(self, scenario: Scenario, seed: int) -> None: ...

    @abstractmethod
    def act(self, state: np.ndarray) -> np.ndarray: ...

    def metadata(self) -> dict:
        """Per-episode facts for the episodes table (the expert reports its planner)."""
        return {}


def goal_seeking_accel(controller: Controller, state: np.ndarray, goal: np.ndarray, cruise: float,
                       brake_accel: float = 1.0) -> np.ndarray:
    """PD towards the goal: aim for a velocity along the line of sight that slows on arrival."""
    p, *_ = controller.unpack(state)
    to_goal = goal - p
    dist = float(np.linalg.norm(to_goal))
    if dist < 1e-9:
        return controller.track_accel(state, goal, np.zeros(3))
    speed = min(cruise, np.sqrt(2.0 * brake_accel * dist) + 0.3)
    v_ref = to_goal / dist * speed
    # Position error is along v_ref already; damp the velocity error only (pure pursuit).
    return controller.track_accel(state, p, v_ref)


def face(controller: Controller, state: np.ndarray, direction: np.ndarray) -> np.ndarray:
    _, _, R, *_ = controller.unpack(state)
    if np.linalg.norm(direction) < 1e-6:
        return R
    return look_rotation(direction, fallback=R)
