"""Moving obstacles in the planner's cost: each rollout step meets the obstacles where they will be
then (the oracles' exact motion, or the tracker's estimate), and the static planner is unchanged.

The tracker is fed the points a depth map of synthetic spheres gives: each cell's z-depth is cast
exactly from the camera to the nearest sphere, then back-projected by the planner's own
``depth_to_points``, so it sees only the near faces, through the 16x16 map's coarse cells.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from scenes import sphere_depth, state_at

from orbitdata.fly.pilot import Task
from orbitdata.fly.rollout import fly_episode
from orbitdata.scenario.dynamics import DebrisMotion, Dynamics
from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.schema import DT
from orbitdata.seeding import grid_seed
from orbitdata.sim.config import CameraConfig, SimConfig
from orbitdata.sim.env import CubeSatEnv
from orbitmodel.plan.config import PlannerConfig, planner_config, recorded
from orbitmodel.plan.cost import trajectory_cost
from orbitmodel.plan.dynamics import RigidBodyDynamics
from orbitmodel.plan.factory import sensor_depth
from orbitmodel.plan.mppi import MPPIConfig
from orbitmodel.plan.obstacles import Camera, PointCloud, TrueObstacles, border_points, depth_to_points, signed_distance
from orbitmodel.plan.pilot import OraclePilot, PlannerPilot, Variant
from orbitmodel.plan.tracker import MovingCloud, Tracker, TrackerConfig, fit_velocity

torch.set_num_threads(1)
CAMERA = Camera.from_sim(SimConfig())
H = 50  # a 2 s plan


def depth_map(position, spheres) -> np.ndarray:
    return sphere_depth(CAMERA, position, spheres)


def watch(tracker: Tracker, spheres, frames: int, camera_velocity=(0.0, 0.0, 0.0)) -> float:
    """Feed ``tracker`` ``frames`` frames of ``spheres`` [(centre at t = 0, velocity, radius)] seen
    from a body drifting at ``camera_velocity`` from the origin; returns the last frame's time."""
    for f in range(frames):
        t = f * DT
        position = np.asarray(camera_velocity) * t
        depth = depth_map(position, [(np.add(c, np.multiply(v, t)), r) for c, v, r in spheres])
        points, radii = depth_to_points(depth, state_at(position), CAMERA, support=1)
        tracker.add(points, radii, t, border_points(depth, CAMERA, support=1))
    return (frames - 1) * DT


def exact_gap(x: np.ndarray, centre, velocity, radius: float, t: float) -> np.ndarray:
    return np.linalg.norm(x - (np.asarray(centre) + np.asarray(velocity) * t), axis=-1) - radius


def facing_shell(centre: np.ndarray, radius: float, viewpoint: np.ndarray) -> np.ndarray:
    """(30, 3) points 0 to 0.4 m off the surface of a sphere, spread over the side facing ``viewpoint``."""
    toward = (viewpoint - centre) / np.linalg.norm(viewpoint - centre)
    side = np.cross(toward, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, toward)
    out = []
    for gap in (0.0, 0.2, 0.4):
        for a in (-0.8, -0.4, 0.0, 0.4, 0.8):
            for b in (-0.4, 0.4):
                d = toward + a * side + b * up
                out.append(centre + (radius + gap) * d / np.linalg.norm(d))
    return np.array(out)


def the_track(tracker: Tracker, centre) -> object:
    """The track whose newest points lie nearest to ``centre``."""
    return min(tracker.tracks, key=lambda t: np.linalg.norm(t.frames[-1].points.mean(0) - centre))


# ---- the tracker ---------------------------------------------------------------------------------
def test_the_tracker_estimates_a_moving_sphere_velocity_and_predicts_where_it_will_be():
    centre, velocity, radius = np.array([2.6, -0.6, 0.3]), np.array([-0.4, 0.7, -0.2]), 0.6
    tracker = Tracker()
    now = watch(tracker, [(centre, velocity, radius)], 30, camera_velocity=(0.5, 0.0, 0.0))
    assert len(tracker.tracks) == 1
    error = np.linalg.norm(tracker.tracks[0].velocity - velocity)
    assert error < 0.15, (tracker.tracks[0].velocity, velocity)  # the truth is 0.83 m/s
    # 1 s ahead, around the face it will show: the exact clearance of the moved sphere, to within
    # the cloud's cells (a point is a sphere half a cell wide) and the velocity's error.
    ahead = now + 1.0
    x = facing_shell(centre + velocity * ahead, radius, np.r_[0.5 * now, 0, 0])
    field = tracker.field(now, reach=5.0)
    got = field.clearance(torch.tensor(x[:, None], dtype=torch.float32), torch.tensor([ahead])).numpy()[:, 0]
    truth = exact_gap(x, centre, velocity, radius, ahead)
    assert np.abs(got - truth).max() < 0.25, np.c_[got, truth]
    # The same points held still (the static planner's belief) are wrong by its motion.
    still = field.clearance(torch.tensor(x, dtype=torch.float32)).numpy()
    assert np.abs(still - truth).max() > 0.45


def test_two_spheres_moving_differently_are_tracked_apart():
    spheres = [
        (np.array([2.8, -1.1, 0.0]), np.array([0.0, -0.4, 0.4]), 0.5),
        (np.array([2.8, 1.1, 0.2]), np.array([-0.6, 0.2, -0.3]), 0.5),
    ]
    tracker = Tracker()
    now = watch(tracker, spheres, 30)
    assert len(tracker.tracks) == 2
    for centre, velocity, _ in spheres:
        track = the_track(tracker, centre + velocity * now)
        assert np.linalg.norm(track.velocity - velocity) < 0.15, (track.velocity, velocity)
    assert the_track(tracker, spheres[0][0]) is not the_track(tracker, spheres[1][0] + spheres[1][1] * now)


def test_a_still_sphere_gets_no_velocity_from_a_moving_camera():
    tracker = Tracker()
    watch(tracker, [(np.array([3.2, 0.3, -0.2]), np.zeros(3), 0.6)], 30, camera_velocity=(1.0, 0.1, 0.0))
    assert len(tracker.tracks) == 1
    assert np.linalg.norm(tracker.tracks[0].velocity) < 0.15  # against 1 m/s of the camera's own motion


def test_a_track_seen_in_fewer_than_min_frames_stands_still_and_the_speed_is_capped():
    sphere = [(np.array([2.6, -0.3, 0.0]), np.array([0.0, 0.8, 0.0]), 0.6)]
    glimpse = Tracker(TrackerConfig(min_frames=8))
    watch(glimpse, sphere, 7)
    assert [t.velocity.tolist() for t in glimpse.tracks] == [[0.0, 0.0, 0.0]]
    capped = Tracker(TrackerConfig(speed_cap=0.3))
    watch(capped, sphere, 30)
    assert np.linalg.norm(capped.tracks[0].velocity) == pytest.approx(0.3)


def test_confidence_drops_a_slope_no_larger_than_its_noise_and_keeps_a_clear_one():
    rng = np.random.default_rng(0)
    times = np.arange(25) * DT
    wander = rng.normal(0.0, 1.0, (25, 3))
    still = np.array([3.0, 0.0, 0.0]) + 0.15 * wander  # a coarse map's centroid, 0.15 m each axis
    moving = np.array([3.0, 0.0, 0.0]) + 0.05 * wander + np.outer(times, [0.0, 0.8, 0.0])
    # Unshrunk, a still object's wandering centroid gets a speed of its own; three standard
    # errors of the fit drop it, and the exact shrinkage is v (1 - 9 se^2 / |v|^2).
    raw = fit_velocity(times, still)
    assert np.linalg.norm(raw) > 0.1
    assert fit_velocity(times, still, confidence=3.0).tolist() == [0.0, 0.0, 0.0]
    dt = times - times.mean()
    se2 = ((still - still.mean(0) - dt[:, None] * raw) ** 2).sum() / 23 / (dt**2).sum()
    shrunk = fit_velocity(times, still, confidence=0.5)
    np.testing.assert_allclose(shrunk, raw * max(0.0, 1 - 0.25 * se2 / (raw @ raw)), rtol=1e-12)
    # A slope well above its noise (0.05 m) loses only a sliver and keeps its direction.
    kept = fit_velocity(times, moving, confidence=3.0)
    assert np.linalg.norm(kept - [0.0, 0.8, 0.0]) < 0.1
    assert (
        kept @ fit_velocity(times, moving) / np.linalg.norm(kept) / np.linalg.norm(fit_velocity(times, moving)) > 0.999
    )
    with pytest.raises(ValueError, match="confidence"):
        TrackerConfig(confidence=-1.0)


def test_a_track_out_of_view_is_carried_along_then_forgotten():
    tracker = Tracker(TrackerConfig(forget=5))
    watch(tracker, [(np.array([2.6, -0.3, 0.0]), np.array([0.0, 0.6, 0.0]), 0.6)], 30)
    (track,) = tracker.tracks
    for f in range(4):
        tracker.add(np.zeros((0, 3)), np.zeros(0), (30 + f) * DT)
    assert tracker.tracks == [track] and track.unseen == 4
    tracker.add(np.zeros((0, 3)), np.zeros(0), 34 * DT)
    assert tracker.tracks == []


# ---- the time-indexed cost -----------------------------------------------------------------------
RADIUS, PATH_SPEED, NOW_FRAME = 0.4, 1.5, 30
NOW = NOW_FRAME * DT


def straight_path() -> torch.Tensor:
    """(1, H, 16) states flying +x at PATH_SPEED from the origin, frames NOW+1 .. NOW+H."""
    s = torch.tensor(state_at((0.0, 0.0, 0.0))).repeat(1, H, 1)
    s[0, :, 0] = PATH_SPEED * DT * torch.arange(1, H + 1)
    s[0, :, 3] = PATH_SPEED  # body velocity: along the camera axis
    return s


def plan_times() -> torch.Tensor:
    return (NOW_FRAME + 1 + torch.arange(H, dtype=torch.float64)) * DT


# A sphere that will cross the path (0.8 m/s along +y, on it 1.4 s from now), and one on the path
# now that leaves it (1 m/s along +y); centres at t = 0 of the episode.
CROSSING = (np.array([2.1, -0.8 * (NOW + 1.4), 0.0]), np.array([0.0, 0.8, 0.0]))
LEAVING = (np.array([2.1, -1.0 * NOW, 0.0]), np.array([0.0, 1.0, 0.0]))


def moving_scenario(centre, velocity) -> Scenario:
    sphere = Obstacle("sphere", tuple(centre), (RADIUS, 0.0, 0.0))
    return Scenario((sphere,), goal=(6.0, 0.0, 0.0), dynamics=Dynamics(debris=(DebrisMotion(tuple(velocity)),)))


def field_for(motion: str, centre, velocity):
    if motion == "tracker":
        tracker = Tracker(TrackerConfig(confidence=0.0))
        assert watch(tracker, [(centre, velocity, RADIUS)], NOW_FRAME + 1) == pytest.approx(NOW)
        return tracker.field(NOW, reach=1.0)
    return TrueObstacles(moving_scenario(centre, velocity), motion).now(NOW)


@pytest.mark.parametrize("motion", ["true", "tracker", "frozen"])
def test_the_cost_meets_each_step_where_the_obstacle_will_be(motion):
    c = PlannerConfig().cost
    costs = {}
    for name, (centre, velocity) in {"crossing": CROSSING, "leaving": LEAVING}.items():
        field = field_for(motion, centre, velocity)
        _, terms = trajectory_cost(
            straight_path(), torch.zeros(1, H, 8), torch.tensor([6.0, 0, 0]), 0.5, field, c, plan_times()
        )
        costs[name] = (float(terms["crash"]), float(terms["collision"]))
    hit, clear = ("leaving", "crossing") if motion == "frozen" else ("crossing", "leaving")
    assert costs[hit][0] == c.crash and costs[hit][1] > 0, costs
    assert costs[clear] == (0.0, 0.0), costs


def test_clouds_out_of_reach_are_skipped_and_the_answer_is_unchanged():
    """A moving cloud that no candidate can reach at any step is not queried; the clearances are
    the minimum over every cloud's own answer to the bit, NaN for a diverged candidate included."""
    rng = np.random.default_rng(5)
    centres = ([2.0, 0, 0], [6.0, 1, 0], [-30.0, 0, 0], [0, 40.0, 0], [3.0, -2, 1], [-5.5, 0, 0])
    velocities = ([0, 0, 0], [0.5, -0.3, 0.2], [0, 0, 0], [0.4, 0.1, -1.0], [0, 0, 0], [2.0, 0, 0])
    # the last one starts out of reach and comes within it during the horizon
    clouds = [
        (rng.normal(c, 0.3, (30, 3)), rng.uniform(0.05, 0.2, 30), np.array(v)) for c, v in zip(centres, velocities)
    ]
    field = MovingCloud(clouds, time=1.0, reach=2.0)
    x = torch.tensor(rng.uniform([-1, -3, -2], [7, 3, 3], (32, 50, 3)), dtype=torch.float32)
    x[3, 20:] = float("nan")
    times = 1.0 + torch.arange(50) * 0.04
    ahead = (times.double() - 1.0).float()[:, None]
    every = torch.full(x.shape[:-1], float("inf"))
    for cloud, velocity in field.clouds:
        every = torch.minimum(every, cloud.clearance(x - ahead * velocity if velocity.any() else x))
    got = field.clearance(x, times)
    assert torch.isnan(got[3, 20:]).all() and torch.isfinite(got).sum() > 300
    assert torch.isfinite(field.clouds[-1][0].clearance(x - ahead * field.clouds[-1][1])).any()
    torch.testing.assert_close(got, every, rtol=0, atol=0, equal_nan=True)
    torch.testing.assert_close(field.clearance(x), field.clearance(x, None), rtol=0, atol=0, equal_nan=True)


def test_true_motion_is_the_exact_pose_at_each_step():
    box = Obstacle("box", (2.0, 0.5, -0.3), (0.4, 0.2, 0.3), quat=(0.9, 0.1, 0.3, 0.2))
    ball = Obstacle("sphere", (1.0, -1.0, 0.5), (0.3, 0.0, 0.0))
    motions = (DebrisMotion((-0.4, 0.2, 0.1), (0.3, -0.2, 0.4)), DebrisMotion((0.1, 0.5, 0.0)))
    scenario = Scenario((box, ball), (6.0, 0, 0), dynamics=Dynamics(motions, cw=True, mean_motion=0.00113))
    x = torch.rand(4, 6, 3, generator=torch.Generator().manual_seed(0)) * 3 - 0.5  # (K, H, 3)
    times = torch.tensor([0.0, 0.5, 1.0, 2.0, 4.0, 8.0], dtype=torch.float64)
    got = TrueObstacles(scenario, "true").clearance(x, times)
    for h, t in enumerate(times.tolist()):
        want = torch.stack([signed_distance(ob, x[:, h]) for ob in scenario.obstacles_at(t)]).amin(0)
        assert torch.allclose(got[:, h], want, atol=1e-5)
    frozen = TrueObstacles(scenario, "frozen").now(1.0).clearance(x, times)
    want = torch.stack([signed_distance(ob, x) for ob in scenario.obstacles_at(1.0)]).amin(0)
    assert torch.allclose(frozen, want, atol=1e-5)


def test_fields_of_still_obstacles_ignore_the_times():
    x = torch.rand(3, 7, 3, generator=torch.Generator().manual_seed(1)) * 3
    times = torch.arange(7, dtype=torch.float64) * 0.3
    still = Scenario((Obstacle("sphere", (1.5, 0.2, 0.0), (0.5, 0, 0)),), (6.0, 0, 0))
    points = np.random.default_rng(0).uniform(0, 3, (40, 3))
    for field in (
        TrueObstacles(still),
        TrueObstacles(still, "frozen").now(2.0),
        PointCloud(points, np.full(40, 0.1)),
        MovingCloud([(points, np.full(40, 0.1), np.zeros(3))], 0.0),
    ):
        assert torch.equal(field.clearance(x, times), field.clearance(x))


# ---- the planner setting -------------------------------------------------------------------------
SIM = SimConfig(camera=CameraConfig(image_size=32), max_steps=10)
SMALL = PlannerConfig(mppi=MPPIConfig(samples=8, horizon=6))


class OldCallField:
    """A field with the one-argument ``clearance`` of the static planner: it refuses times."""

    def __init__(self, field):
        self.field, self.points = field, field.points

    def __len__(self):
        return len(self.field)

    def clearance(self, positions):
        return self.field.clearance(positions)


class OldCallPilot(PlannerPilot):
    def _obstacles(self, obs, depth):
        return OldCallField(super()._obstacles(obs, depth))


def sensor_pilot(cls=PlannerPilot, **changes) -> PlannerPilot:
    """The rendered depth through the planner's obstacle code, planning with the design's body (not
    handed the scenario, whose body a moving-debris episode would give it): these tests are about the obstacles."""
    config = dataclasses.replace(SMALL, **changes)
    pilot = cls(Variant.ORACLE_TRUE_DYN_SENSOR, RigidBodyDynamics(SIM), sensor_depth, Camera.from_sim(SIM), config, SIM)
    pilot.privileged = False
    return pilot


def fly(pilot, scenario=None) -> np.ndarray:
    env = CubeSatEnv(SIM)
    result = fly_episode(env, pilot, grid_seed(0, 3, 1.0, 2), 3, 1.0, scenario=scenario)
    env.close()
    return result.actions


def test_the_static_planner_flies_the_old_call_path_to_the_bit():
    assert np.array_equal(fly(sensor_pilot()), fly(sensor_pilot(OldCallPilot)))


def test_the_tracking_planner_follows_a_rendered_moving_sphere():
    centre, velocity = (2.6, -0.9, 0.0), (0.0, 0.6, 0.0)
    unshrunk = sensor_pilot(obstacle_motion="tracker", tracker=TrackerConfig(confidence=0.0))
    actions = fly(unshrunk, moving_scenario(centre, velocity))
    assert len(actions) > 5 and np.isfinite(actions).all()
    (track,) = unshrunk.tracker.tracks  # the rendered depth_low, through the pilot's own cell filter
    assert np.linalg.norm(track.velocity - velocity) < 0.2, track.velocity  # the truth is 0.6 m/s
    # The default shrinks the short track's slope towards zero by its noise: slower, same direction.
    pilot = sensor_pilot(obstacle_motion="tracker")
    fly(pilot, moving_scenario(centre, velocity))
    (track,) = pilot.tracker.tracks
    speed = np.linalg.norm(track.velocity)
    assert 0.05 < speed <= np.linalg.norm(unshrunk.tracker.tracks[0].velocity), track.velocity
    assert track.velocity @ velocity / speed / 0.6 > 0.9, track.velocity


def test_the_oracles_take_true_or_frozen_and_the_planner_static_or_tracker():
    with pytest.raises(ValueError, match="obstacle_motion=tracker"):
        OraclePilot(Variant.ORACLE_TRUE, RigidBodyDynamics(SIM), None, CAMERA, PlannerConfig(obstacle_motion="tracker"))
    with pytest.raises(ValueError, match="obstacle_motion=true"):
        sensor_pilot(obstacle_motion="true")
    with pytest.raises(ValueError, match="obstacle_motion"):
        PlannerConfig(obstacle_motion="psychic")
    oracle = OraclePilot(Variant.ORACLE_TRUE, RigidBodyDynamics(SIM), None, CAMERA, SMALL)
    task = Task(goal=(6.0, 0.0, 0.0), goal_radius=0.5, initial_velocity=(0.0, 0.0, 0.0), seed=0)
    with pytest.raises(ValueError, match="obstacle_motion=true"):  # moving debris: say which oracle
        oracle.reset(task, scenario=moving_scenario(*CROSSING))


def test_the_settings_record_the_motion_and_the_tracker_only_when_not_static():
    plain = recorded(planner_config("cpu"))
    assert "obstacle_motion" not in plain and "tracker" not in plain
    assert "tracker" not in recorded(planner_config("cpu", obstacle_motion="true"))
    tracked = recorded(planner_config("cpu", obstacle_motion="tracker", window="30", speed_cap="1.2"))
    assert tracked["obstacle_motion"] == "tracker"
    assert tracked["tracker"] == dataclasses.asdict(TrackerConfig(window=30, speed_cap=1.2))
    with pytest.raises(ValueError, match="min_frames"):
        planner_config("cpu", obstacle_motion="tracker", min_frames="40")


def test_the_oracles_fly_moving_debris_true_or_frozen():
    # On the way to the goal now, gone from it in a second: the frozen oracle plans against it where it
    # stands, the true one against where it will be, so the same episode flies other thrusts.
    scenario = dataclasses.replace(moving_scenario((1.2, 0.0, 0.0), (0.0, 1.0, 0.0)), goal=(4.0, 0.0, 0.0))
    plans = {}
    for motion in ("true", "frozen"):
        config = PlannerConfig(mppi=MPPIConfig(samples=8, horizon=25), obstacle_motion=motion)
        oracle = OraclePilot(Variant.ORACLE_TRUE, RigidBodyDynamics(SIM), None, CAMERA, config, SIM)
        plans[motion] = fly(oracle, scenario)
        assert np.isfinite(plans[motion]).all()
    assert not np.array_equal(plans["true"], plans["frozen"])  # they expect different futures
