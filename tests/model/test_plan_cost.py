"""The planner's cost: zero collision cost far from obstacles, high inside the inflated hull."""

from __future__ import annotations

import numpy as np
import torch

from orbitmodel.plan.cost import CostConfig, collision_ramp, trajectory_cost
from orbitmodel.plan.obstacles import PointCloud

torch.set_num_threads(1)


def states_along(positions: torch.Tensor, velocity=(1.0, 0.0, 0.0)) -> torch.Tensor:
    """(K, H, 3) positions -> (K, H, 16) states, identity attitude, body velocity ``velocity``."""
    K, H, _ = positions.shape
    s = torch.zeros(K, H, 16)
    s[..., 0:3] = positions
    s[..., 3:6] = torch.tensor(velocity)
    s[..., 6], s[..., 9], s[..., 15] = 1.0, 1.0, 1.0
    return s


def test_collision_ramp():
    c = CostConfig()
    clearance = torch.tensor(
        [10.0, c.hull_radius + c.margin + 1e-3, c.hull_radius + c.margin / 2, c.hull_radius, 0.0, -1.0]
    )
    ramp = collision_ramp(clearance, c)
    assert ramp[0] == 0 and ramp[1] == 0
    assert 0 < ramp[2] < 1 and ramp[3] == 1 and ramp[4] == 1 and ramp[5] == 1


def test_collision_cost_is_zero_far_from_every_point_and_high_inside_the_inflated_hull():
    c = CostConfig()
    cloud = PointCloud(np.array([[3.0, 0.0, 0.0], [3.0, 0.3, 0.0]]), np.array([0.2, 0.2]))
    goal = torch.tensor([10.0, 0.0, 0.0])
    H = 31  # 0.2 m apart: one step lands on the points
    # Candidate 0 passes 2 m to the side; candidate 1 flies through the points; candidate 2
    # grazes them inside the margin (clearance between hull and hull + margin).
    xs = torch.linspace(0, 6, H)
    side = torch.stack([xs, torch.full((H,), 2.3), torch.zeros(H)], -1)
    through = torch.stack([xs, torch.zeros(H), torch.zeros(H)], -1)
    graze = torch.stack([xs, torch.full((H,), -0.2 - c.hull_radius - c.margin / 2), torch.zeros(H)], -1)
    states = states_along(torch.stack([side, through, graze]))
    _, terms = trajectory_cost(states, torch.zeros(3, H, 8), goal, 0.5, cloud, c)
    assert terms["collision"][0] == 0 and terms["crash"][0] == 0
    assert terms["crash"][1] == c.crash and terms["collision"][1] >= c.collision
    assert 0 < terms["collision"][2] < terms["collision"][1] and terms["crash"][2] == 0


def test_progress_rewards_arriving_and_stops_counting_after():
    c = CostConfig()
    empty = PointCloud(np.zeros((0, 3)), np.zeros(0))
    goal = torch.tensor([5.0, 0.0, 0.0])
    H = 20
    fast = torch.stack([torch.linspace(0.5, 10, H), torch.zeros(H), torch.zeros(H)], -1)  # through the goal
    slow = torch.stack([torch.linspace(0.5, 4, H), torch.zeros(H), torch.zeros(H)], -1)
    total, terms = trajectory_cost(states_along(torch.stack([fast, slow])), torch.zeros(2, H, 8), goal, 0.5, empty, c)
    assert terms["terminal"][0] == 0 and terms["terminal"][1] > 0
    assert total[0] < total[1]


def test_effort_spin_heading_and_speed_terms():
    c = CostConfig()
    empty = PointCloud(np.zeros((0, 3)), np.zeros(0))
    pos = torch.zeros(2, 5, 3)
    forward, backward = states_along(pos[:1], (1.0, 0, 0)), states_along(pos[:1], (-1.0, 0, 0))
    _, terms = trajectory_cost(torch.cat([forward, backward]), torch.zeros(2, 5, 8), torch.ones(3), 0.5, empty, c)
    assert terms["heading"][0] == 0 and terms["heading"][1] > 0  # the camera looks where it flies
    fast = states_along(pos[:1], (c.max_speed + 1, 0, 0))
    fast[..., 12] = 2.0  # spinning
    _, terms = trajectory_cost(fast, torch.ones(1, 5, 8), torch.ones(3), 0.5, empty, c)
    assert (
        terms["speed"][0] > 0 and terms["spin"][0] > 0 and torch.isclose(terms["effort"][0], torch.tensor(8 * c.effort))
    )


def test_a_speed_scaled_margin_and_urgency_make_fast_and_soon_contacts_costlier():
    from orbitmodel.kinematics import HULL_RADIUS

    cloud = PointCloud(np.array([[0.0, 1.0, 0.0]]), np.array([0.05]), reach=2.0)
    near = torch.tensor([[[0.0, 1.0 - 0.05 - HULL_RADIUS - 0.5, 0.0]]])  # 0.5 m of clearance, beyond a 0.4 m margin
    goal = torch.tensor([50.0, 0.0, 0.0])

    def collision(config, velocity, positions=near):
        states = states_along(positions, velocity)
        _, terms = trajectory_cost(states, torch.zeros(*states.shape[:2], 8), goal, 0.5, cloud, config)
        return float(terms["collision"][0])

    fixed = CostConfig()
    assert collision(fixed, (0.5, 0, 0)) == collision(fixed, (2.0, 0, 0)) == 0.0  # outside the fixed margin
    wide = CostConfig(margin_per_speed=0.2)  # 0.4 + 0.2 |v| m
    assert 0.0 < collision(wide, (1.0, 0, 0)) < collision(wide, (2.0, 0, 0))  # monotone in speed
    far = torch.tensor([[0.0, -5.0, 0.0]]) + torch.zeros(1, 4, 3)
    soon, late = far.clone(), far.clone()
    soon[0, 0], late[0, 3] = near[0, 0], near[0, 0]  # the same near pass at step 0 or at step 3 of 4
    eager = CostConfig(margin=0.6, urgency=1.0)
    assert collision(eager, (1, 0, 0), soon) > collision(eager, (1, 0, 0), late) > 0  # monotone in time to contact
    flat = CostConfig(margin=0.6)
    assert collision(flat, (1, 0, 0), soon) == collision(flat, (1, 0, 0), late)
