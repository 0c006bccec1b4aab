"""The dynamic tier's sampler: a pure function of the seed, every promised range drawn and
recorded, debris aimed at the nominal flight, unsurvivable draws rejected and counted."""

import math
from dataclasses import asdict, replace

import numpy as np
import pyarrow as pa
import pytest

from orbitdata import schema as S
from orbitdata.config import GenerationConfig, build
from orbitdata.scenario import ScenarioConfig, sample_scenario, signed_distance
from orbitdata.scenario.dynamic_sampler import unsurvivable
from orbitdata.scenario.motion import cw_acceleration, free_motion, nominal_flight, tumble
from orbitdata.scenario.spec import Obstacle, Scenario

DYNAMIC = ScenarioConfig.for_tier("dynamic")
SEEDS = range(150)


@pytest.fixture(scope="module")
def scenarios():
    return [sample_scenario(seed, DYNAMIC) for seed in SEEDS]


def with_dynamic(**changes) -> ScenarioConfig:
    return replace(DYNAMIC, dynamic=replace(DYNAMIC.dynamic, **changes))


def test_the_static_tier_is_the_default_and_unchanged():
    assert ScenarioConfig.for_tier("static") == ScenarioConfig() and ScenarioConfig().tier == "static"
    static = sample_scenario(7)
    assert static.dynamics is None and static.tier == "static"
    assert np.array_equal(static.obstacle_poses([0.0, 5.0])[1], static.obstacle_poses(0.0)[0])  # nothing moves
    assert DYNAMIC.tier == "dynamic" and DYNAMIC.n_obstacles == (1, 10) and DYNAMIC.speed == (0.5, 3.0)


def test_the_tier_is_chosen_by_name_in_a_config_table():
    built = build(ScenarioConfig, {"tier": "dynamic", "dynamic": {"cw_prob": 1.0}}, "scenario")
    assert built == replace(DYNAMIC, dynamic=replace(DYNAMIC.dynamic, cw_prob=1.0))
    with pytest.raises(ValueError, match="unknown scenario tier 'moving'; choose one of static, dynamic"):
        build(ScenarioConfig, {"tier": "moving"}, "scenario")
    with pytest.raises(ValueError, match="scenario.tier must be one of static, dynamic"):
        ScenarioConfig(tier="moving")
    # The static tier's record (meta/info.json) is the one from before tiers existed, so its
    # datasets keep their bytes and resume; and it loads back as the static tier.
    stored = GenerationConfig().to_dict()
    assert "tier" not in stored["scenario"] and "dynamic" not in stored["scenario"]
    assert GenerationConfig.from_dict(stored) == GenerationConfig()
    # A dynamic record names its tier and loads back as it.
    dynamic = GenerationConfig.from_dict({"scenario": {"tier": "dynamic"}})
    assert dynamic.scenario == DYNAMIC and dynamic.to_dict()["scenario"]["tier"] == "dynamic"
    assert GenerationConfig.from_dict(dynamic.to_dict()) == dynamic


def test_a_pure_function_of_seed_and_settings(scenarios):
    assert sample_scenario(3, DYNAMIC) == scenarios[3] and scenarios[3] != scenarios[4]
    assert sample_scenario(3, DYNAMIC, n_obstacles=7, speed=3.0) == sample_scenario(
        3, DYNAMIC, n_obstacles=7, speed=3.0
    )
    assert Scenario.from_dict(scenarios[3].to_dict()) == scenarios[3]
    # Each draw has its own stream: a change to the fault leaves the debris, the body and the sensing alone.
    other = sample_scenario(3, with_dynamic(fault_prob=1.0, fault_kinds=("stuck",)))
    assert other.obstacles == scenarios[3].obstacles and other.dynamics.debris == scenarios[3].dynamics.debris
    assert other.dynamics.body == scenarios[3].dynamics.body and other.dynamics.fault.kind == "stuck"


def test_every_range_is_drawn_and_recorded(scenarios):
    d = DYNAMIC.dynamic
    assert {len(s.obstacles) for s in scenarios} == set(range(1, 11))
    speeds = [np.linalg.norm(s.initial_velocity) for s in scenarios]
    assert min(speeds) < 0.7 and 2.8 < max(speeds) <= 3.0
    motions = [m for s in scenarios for m in s.dynamics.debris]
    drift = np.array([np.linalg.norm(m.velocity) for m in motions])  # at t = 0; CW bends it by < 1 %
    assert 0.1 * 0.99 <= drift.min() < 0.15 and 0.95 < drift.max() <= 1.0 * 1.01
    tumble_deg = np.degrees([np.linalg.norm(m.angular_velocity) for m in motions])
    assert tumble_deg.min() < 2.0 and 28.0 < tumble_deg.max() <= 30.0
    assert 0.7 < np.mean([m.intercept for m in motions]) < 0.9
    assert 0.3 < np.mean([s.dynamics.cw for s in scenarios]) < 0.7
    assert all(s.dynamics.mean_motion == 0.00113 for s in scenarios)
    for s in scenarios:
        body = s.dynamics.body
        assert 0.8 <= body.mass_scale <= 1.2 and all(0.8 <= x <= 1.2 for x in body.inertia_scale)
        assert 0.01 <= np.linalg.norm(body.com_offset) <= 0.02
    faults = [s.dynamics.fault for s in scenarios]
    assert {f.kind for f in faults} == {"none", "off", "scaled", "stuck"} and {f.thruster for f in faults} == set(
        range(-1, 8)
    )
    assert all(0.3 <= f.level <= 0.7 for f in faults if f.kind == "scaled")
    assert all(0.05 <= f.level <= 0.10 for f in faults if f.kind == "stuck")
    onsets = [f.onset_time for f in faults if f.kind != "none"]
    assert all(t == 0.0 or 1.0 - 1e-9 <= t <= 4.0 + 1e-9 for t in onsets)
    assert 0.3 < np.mean([t == 0.0 for t in onsets]) < 0.7
    sensing = [s.dynamics.sensing for s in scenarios]
    assert all(x.rgb_noise == d.rgb_noise and 0.05 <= x.depth_dropout <= 0.20 for x in sensing)
    assert 0.1 < np.mean([x.eclipse for x in sensing]) < 0.4
    for s in scenarios:  # in eclipse the sun is out: the lighting record says so
        eclipse = s.dynamics.sensing.eclipse
        assert (s.lighting.sun_intensity == 0.0) == eclipse and (s.lighting.ambient == d.eclipse_ambient) == eclipse


def test_the_start_and_the_goal_stay_clear(scenarios):
    c = DYNAMIC
    for s in scenarios:
        assert min(signed_distance(ob, (0.0, 0.0, 0.0)) for ob in s.obstacles) >= c.start_clearance
        for t in np.arange(0.0, c.dynamic.horizon, 0.2):
            assert min(signed_distance(ob, s.goal) for ob in s.obstacles_at(t)) >= c.goal_radius + c.goal_clearance


def _closest_approach(s: Scenario) -> float:
    """Smallest distance (m) from the nominal straight flight's centre to any debris surface."""
    v = max(np.linalg.norm(s.initial_velocity), DYNAMIC.dynamic.nominal_speed)
    times = np.arange(0.0, DYNAMIC.dynamic.horizon, 0.04)
    path = nominal_flight(s.goal, v, times)
    poses = s.obstacle_poses(times)
    return min(
        signed_distance(replace(ob, center=tuple(pose[:3]), quat=tuple(pose[3:])), p)
        for k, p in enumerate(path)
        for ob, pose in zip(s.obstacles, poses[k])
    )


def test_debris_intercepts_the_nominal_flight():
    """One piece per episode: an unavoiding straight flight meets it; pure drift rarely does."""
    aimed = [_closest_approach(sample_scenario(seed, DYNAMIC, n_obstacles=1)) for seed in range(40)]
    drifting = [
        _closest_approach(sample_scenario(seed, with_dynamic(intercept_prob=0.0), n_obstacles=1)) for seed in range(40)
    ]
    assert np.median(aimed) < 0.5
    assert np.median(drifting) > 1.0


def test_intercepting_debris_is_at_its_aim_point_at_its_crossing_time(scenarios):
    for s in scenarios[:40]:
        for i, m in enumerate(s.dynamics.debris):
            if m.intercept:
                centre = s.obstacle_poses(m.crossing_time)[0, i, :3]
                assert np.allclose(centre, m.aim, atol=1e-9)
                assert abs(m.crossing_time - m.t_star) <= DYNAMIC.dynamic.intercept_jitter + 1e-12
            else:
                assert m.t_star is None and m.aim is None


def test_a_piece_no_pilot_can_escape_is_rejected_and_counted(scenarios):
    times, accel = np.arange(301) * 0.04, DYNAMIC.dynamic.escape_accel
    head_on = Obstacle("sphere", (3.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    assert unsurvivable(head_on, (-1.0, 0.0, 0.0), (3.0, 0.0, 0.0), accel, 0.0, times)  # closing at 4 m/s
    assert not unsurvivable(head_on, (0.0, 0.0, 1.0), (3.0, 0.0, 0.0), accel, 0.0, times)  # it leaves the line
    # Fast debris and a tight start make some draws unsurvivable: they are redrawn and counted.
    hard = replace(with_dynamic(debris_speed=(2.0, 3.0), intercept_along=(0.1, 0.3)), start_clearance=0.5)
    hard_scenarios = [sample_scenario(seed, hard, speed=3.0) for seed in range(30)]
    assert sum(s.dynamics.unsurvivable_draws for s in hard_scenarios) > 0
    for s in hard_scenarios + scenarios[:30]:  # what was kept is escapable
        for ob, m in zip(s.obstacles, s.dynamics.debris):
            assert not unsurvivable(ob, m.velocity, s.initial_velocity, accel, s.dynamics.n, times)


def test_free_motion_solves_the_clohessy_wiltshire_equations():
    n, h = 0.00113, 0.05
    p0, v0 = np.array([3.0, -2.0, 1.5]), np.array([2.0, -0.5, 0.7])
    times = np.array([0.0, 4.0 - h, 4.0, 4.0 + h, 12.0])
    p, v = free_motion(p0, v0, times, n)
    assert np.allclose(p[0], p0) and np.allclose(v[0], v0)
    accel = (p[3] - 2 * p[2] + p[1]) / h**2
    assert np.allclose(accel, cw_acceleration(p[2], v[2], n), rtol=1e-6, atol=1e-10)
    assert np.allclose((p[3] - p[1]) / (2 * h), v[2], rtol=1e-6)
    back_p, back_v = free_motion(p[4], v[4], [-12.0], n)  # it runs backwards too
    assert np.allclose(back_p[0], p0) and np.allclose(back_v[0], v0)
    straight, _ = free_motion(p0, v0, [12.0], 0.0)
    assert np.allclose(straight[0], p0 + 12.0 * v0)


def test_tumble_turns_at_the_drawn_rate():
    omega = np.radians([0.0, 0.0, 30.0])
    q = tumble((1.0, 0.0, 0.0, 0.0), omega, [0.0, 3.0])  # 90 degrees about z in 3 s
    assert np.allclose(q[1], [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])


def test_the_episode_record_fits_the_proposed_columns(scenarios):
    for s in scenarios[:20]:
        dyn = s.dynamics
        pa.array([[asdict(m) for m in dyn.debris]], type=pa.list_(S.DEBRIS_MOTION_STRUCT))
        pa.array([asdict(dyn.body)], type=S.BODY_STRUCT)
        pa.array([asdict(dyn.fault)], type=S.FAULT_STRUCT)
        pa.array([asdict(dyn.sensing)], type=S.SENSING_STRUCT)
        poses = s.obstacle_poses(1.0)[0]
        pa.array([poses.tolist()], type=S.DYNAMIC_STEP_FIELDS[0].type)
    for struct, record in ((S.BODY_STRUCT, dyn.body), (S.FAULT_STRUCT, dyn.fault), (S.SENSING_STRUCT, dyn.sensing)):
        assert [f.name for f in struct] == list(asdict(record))
    assert [f.name for f in S.DEBRIS_MOTION_STRUCT] == list(asdict(dyn.debris[0]))
