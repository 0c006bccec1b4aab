"""The planner's objective: reach the goal, never touch an obstacle, spend little, fly steadily.

For imagined states (K, H, 16) and their thrusts (K, H, 8), per candidate and summed over the
steps before it reaches the goal (the episode ends there, so nothing after counts). Step k's
clearance is taken against the obstacles where the field puts them at ``times[k]`` (the rollout
step's time; a field of still obstacles ignores it)::

    collision  w_c  * u_k * ramp(clearance)^2        ramp: 1 at the hull, 0 at hull + margin (+ margin_per_speed |v|)
                                                      u_k = 1 + urgency (1 - k / H): a contact sooner costs more
    crash      w_x  * [any clearance < hull]          once per candidate
    progress   w_p  * |p - goal| / H                  metres, so arriving sooner is cheaper
    terminal   w_T  * |p_H - goal|                    where it ends up, unless it arrived
    effort     w_e  * sum(thrust) / H                 fuel (mass flow is proportional to thrust)
    spin       w_s  * |w|^2 / H                       (rad/s)^2: a steady camera and attitude
    heading    w_h  * (1 - cos(camera axis, velocity)) / H    look where you fly (the depth map)
    speed      w_v  * max(|v| - v_max, 0)^2 / H       do not outrun what the camera can see
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch

from orbitmodel.kinematics import HULL_RADIUS, P, V, W


class ObstacleField(Protocol):
    def clearance(self, positions: torch.Tensor, times: torch.Tensor | None = None) -> torch.Tensor:
        """(..., H, 3) metres, row h at ``times[h]`` (H,) seconds into the episode -> (..., H)
        metres to the nearest obstacle surface then (+inf if none near). Obstacles that do not
        move ignore ``times``; None: where the field holds them now."""


@dataclass(frozen=True)
class CostConfig:
    """Weights (cost units per the unit named) and the geometry of the collision ramp.

    Args:
        hull_radius: metres, the bounding sphere of the 1U hull (orbitdata's ``CubeSatConfig``).
        margin: metres of clearance beyond the hull where the collision ramp starts.
        margin_per_speed: seconds: the ramp starts ``margin + margin_per_speed * |v|`` beyond the
            hull, a wider berth at speed (0: a fixed margin).
        urgency: the collision term of step k of H is weighted 1 + urgency (1 - k / H), so the
            same clearance costs more the sooner it comes (0: every step alike).
        collision, crash, progress, terminal, effort, spin, heading, speed: the weights above.
        max_speed: m/s above which the speed term applies.
        goal_fraction: a candidate counts as arrived within this fraction of the goal radius
            (a little inside it, so the plan does not graze the edge).
    """

    hull_radius: float = HULL_RADIUS
    margin: float = 0.4
    margin_per_speed: float = 0.0
    urgency: float = 0.0
    collision: float = 20.0
    crash: float = 200.0
    progress: float = 1.0
    terminal: float = 1.0
    effort: float = 0.05
    spin: float = 0.05
    heading: float = 3.0
    speed: float = 5.0
    max_speed: float = 2.0
    goal_fraction: float = 0.6

    def __post_init__(self):
        if self.margin <= 0 or self.hull_radius < 0:
            raise ValueError(f"margin={self.margin} must be > 0 and hull_radius={self.hull_radius} >= 0")
        if any(
            getattr(self, k) < 0
            for k in (
                "collision",
                "crash",
                "progress",
                "terminal",
                "effort",
                "spin",
                "heading",
                "speed",
                "margin_per_speed",
                "urgency",
            )
        ):
            raise ValueError("cost weights must be >= 0")


def collision_ramp(clearance: torch.Tensor, config: CostConfig, speed: torch.Tensor | None = None) -> torch.Tensor:
    """(...,) metres centre-to-surface -> (...,) in [0, 1]: 0 beyond hull + margin, 1 at the hull;
    with ``speed`` (...,) m/s the margin grows by ``margin_per_speed`` seconds of it."""
    margin = config.margin if speed is None else config.margin + config.margin_per_speed * speed
    gap = clearance - config.hull_radius
    return (1 - gap / margin).clamp(0, 1) ** 2


def trajectory_cost(
    states: torch.Tensor,
    actions: torch.Tensor,
    goal: torch.Tensor,
    goal_radius: float,
    obstacles: ObstacleField,
    config: CostConfig = CostConfig(),
    times: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict]:
    """states (K, H, 16), actions (K, H, 8) thrust in [0,1], goal (3,) metres -> cost (K,) and its terms.
    ``times`` (H,) seconds: when each step's state is reached, for a field whose obstacles move
    (None: the field's obstacles as they stand, the static planner's call)."""
    c = config
    H = states.shape[1]
    p = states[..., P]  # (K, H, 3) metres, world
    v = states[..., V]  # (K, H, 3) m/s, body
    dist = (p - goal).norm(dim=-1)  # (K, H) metres
    arrived = torch.cummax((dist < c.goal_fraction * goal_radius).int(), 1).values.bool()  # (K, H)
    # The step that arrives still counts (it must be collision-free); the ones after do not.
    live = torch.cat([torch.ones_like(arrived[:, :1]), ~arrived[:, :-1]], 1).float()  # (K, H)
    clearance = obstacles.clearance(p) if times is None else obstacles.clearance(p, times)  # (K, H) metres
    speed = v.norm(dim=-1)  # (K, H)
    urgency = 1 + c.urgency * (1 - torch.arange(H, dtype=states.dtype, device=states.device) / H)  # (H,) sooner: more
    terms = {
        "collision": c.collision * (collision_ramp(clearance, c, speed) * urgency * live).sum(1),
        "crash": c.crash * ((clearance < c.hull_radius).float() * live).amax(1),
        "progress": c.progress * (dist * live).sum(1) / H,
        "terminal": c.terminal * dist[:, -1] * (~arrived[:, -1]).float(),
        "effort": c.effort * (actions.sum(-1) * live).sum(1) / H,
        "spin": c.spin * ((states[..., W] ** 2).sum(-1) * live).sum(1) / H,
        "heading": c.heading * ((1 - v[..., 0] / speed.clamp(min=0.1)) * live).sum(1) / H,
        "speed": c.speed * ((speed - c.max_speed).clamp(min=0) ** 2 * live).sum(1) / H,
    }
    return sum(terms.values()), terms
