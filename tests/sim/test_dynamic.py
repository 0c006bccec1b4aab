"""The simulator in the dynamic tier: debris where its analytic motion says, the CW terms when
flagged (and never in the static tier), the body and the fault exactly as recorded, the noisy
camera, and the same bytes for the same seed."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from orbitdata.fly.pilot import Pilot, Task
from orbitdata.fly.rollout import fly_episode
from orbitdata.scenario import ScenarioConfig, sample_scenario
from orbitdata.scenario.dynamics import DebrisMotion, ThrusterFault
from orbitdata.scenario.motion import free_motion
from orbitdata.scenario.spec import Obstacle
from orbitdata.sim import CameraConfig, CubeSatEnv, SimConfig, wrench_matrix
from orbitdata.sim.dynamic import body_mass_properties, sense
from orbitdata.sim.mjcf import BODY

DYNAMIC = ScenarioConfig.for_tier("dynamic")
DT = 0.04


@pytest.fixture
def dynamic_env():
    env = CubeSatEnv(SimConfig(render=False), DYNAMIC)
    yield env
    env.close()


def empty_space(seed: int = 0, **dynamics):
    """A dynamic-tier scenario with no debris, the CubeSat at rest, and ``dynamics`` changed."""
    base = sample_scenario(seed, DYNAMIC)
    dyn = replace(base.dynamics, debris=(), **dynamics)
    return replace(base, obstacles=(), dynamics=dyn, initial_velocity=(0.0, 0.0, 0.0), goal=(60.0, 0.0, 0.0))


def com_velocity(env) -> np.ndarray:
    """m/s, world frame: the centre of mass's velocity (a free joint's qvel is the cube centre's)."""
    d, b = env.data, mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_BODY, BODY)
    omega = d.xmat[b].reshape(3, 3) @ d.qvel[3:6]
    return d.qvel[0:3] + np.cross(omega, d.xipos[b] - d.xpos[b])


def test_debris_poses_equal_their_analytic_motion(dynamic_env):
    env = dynamic_env
    obs, info = env.reset(seed=11, options={"n_obstacles": 6})
    scn = env.scenario
    geoms = [mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_GEOM, f"obstacle{i}") for i in range(6)]
    t = 0
    while True:
        expected = scn.obstacle_poses(t * DT)[0]  # (N, 7)
        assert np.array_equal(info["obstacle_poses"], expected)
        assert np.allclose(env.data.geom_xpos[geoms], expected[:, :3], rtol=0, atol=1e-12)  # where it collides
        for g, pose in zip(geoms, expected):  # and turned as recorded (the geom's frame is the body's)
            R = np.empty(9)
            mujoco.mju_quat2Mat(R, pose[3:])
            assert np.allclose(env.data.geom_xmat[g], R, atol=1e-12)
        if info["outcome"] is not None or t == 60:
            break
        obs, _, _, _, info = env.step(np.zeros(8))
        t += 1
    moved = np.linalg.norm(scn.obstacle_poses(t * DT)[0, :, :3] - scn.obstacle_poses(0.0)[0, :, :3], axis=1)
    assert moved.min() > 0.1 * t * DT * 0.9  # every piece drifts at >= 0.1 m/s
    assert "obstacle_poses" not in obs and set(obs) == {"state"}  # privileged: in info, never observed


def test_the_cubesat_collides_with_debris_and_debris_not_with_itself(dynamic_env):
    env = dynamic_env
    base = empty_space()
    crossing = (
        Obstacle("box", (3.0, 1.0, 0.0), (0.3, 0.3, 0.3)),
        Obstacle("sphere", (3.0, -1.0, 0.0), (0.3, 0.0, 0.0)),
    )
    passing = (DebrisMotion((0.0, -1.0, 0.0)), DebrisMotion((0.0, 1.0, 0.0)))  # through each other at t = 1 s
    scn = replace(base, obstacles=crossing, dynamics=replace(base.dynamics, debris=passing))
    env.reset(options={"scenario": scn})
    for _ in range(40):
        _, _, terminated, _, info = env.step(np.zeros(8))
        assert env.data.ncon == 0 and not terminated  # overlapping debris makes no contact
    incoming = (Obstacle("sphere", (2.5, 0.0, 0.0), (0.4, 0.0, 0.0)),)
    scn = replace(base, obstacles=incoming, dynamics=replace(base.dynamics, debris=(DebrisMotion((-1.0, 0, 0)),)))
    env.reset(options={"scenario": scn})
    while info := env.step(np.zeros(8))[4]:
        if info["outcome"] is not None:
            break
    assert info["outcome"] == "collision" and 1.9 < info["step"] * DT < 2.1  # it hits the still CubeSat at ~2 s


@pytest.mark.parametrize("cw", [True, False])
def test_clohessy_wiltshire_terms_act_when_flagged(dynamic_env, cw):
    """Coasting at 2 m/s radially for 10 s: the CW drift (~0.23 m along-track), or none."""
    env = dynamic_env
    scn = replace(empty_space(cw=cw), initial_velocity=(2.0, 0.0, 0.0))
    env.reset(options={"scenario": scn})
    com0 = env.data.xipos[1].copy()
    for _ in range(250):
        obs, *_ = env.step(np.zeros(8))
    expected, _ = free_motion(com0, (2.0, 0.0, 0.0), [10.0], scn.dynamics.n)
    assert np.allclose(env.data.xipos[1], expected[0], atol=5e-4)  # the integrator follows the closed form
    drift = np.linalg.norm(obs["state"][:3] - np.array([20.0, 0.0, 0.0]))
    if cw:
        assert 0.20 < drift < 0.25 and obs["state"][1] < 0  # a_y = -2 n v_x: it falls behind along-track
    else:
        assert drift < 1e-5


def test_the_static_tier_has_no_orbital_terms(physics_env):
    env = physics_env
    scn = replace(sample_scenario(0), obstacles=(), initial_velocity=(2.0, 0.0, 0.0), goal=(60.0, 0.0, 0.0))
    env.reset(options={"scenario": scn})
    for _ in range(250):
        obs, *_ = env.step(np.zeros(8))
    assert np.allclose(obs["state"][:3], [20.0, 0.0, 0.0], atol=1e-5)
    assert not env.data.xfrc_applied.any() and env.model.nmocap == 0


def test_the_body_is_built_as_recorded(dynamic_env):
    env = dynamic_env
    env.reset(seed=4)
    body, sim = env.scenario.dynamics.body, env.sim
    b = mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_BODY, BODY)
    mass, inertia = body_mass_properties(sim.cubesat, body.mass_scale, body.inertia_scale, sim.cubesat.fuel_mass)
    assert env.model.body_mass[b] == pytest.approx(mass) and np.allclose(env.model.body_inertia[b], inertia)
    assert np.allclose(env.model.body_ipos[b], body.com_offset)
    assert not np.allclose(inertia, inertia[0])  # no longer isotropic


def _acceleration(env, fault: ThrusterFault, command: np.ndarray, step: int, mass: float, inertia, com):
    """The centre's (qacc) linear and the body-frame angular acceleration that rigid-body physics
    gives for ``command`` with ``fault`` at frame ``step``, from the recorded mass, inertia and centre of mass."""
    d = env.data
    W = wrench_matrix(env.sim.cubesat, com)  # body frame, about the centre of mass
    wrench = W @ fault.apply(command, step)
    R = d.xmat[1].reshape(3, 3)
    w = d.qvel[3:6]  # body frame
    alpha = (wrench[3:] - np.cross(w, inertia * w)) / inertia  # Euler's equations, principal axes
    r = np.asarray(com)  # body frame: cube centre -> centre of mass
    a_com = R @ wrench[:3] / mass
    a_centre = a_com - R @ (np.cross(alpha, r) + np.cross(w, np.cross(w, r)))
    return a_centre, alpha


@pytest.mark.parametrize(
    "fault", [ThrusterFault("off", 2, 0.0, 3), ThrusterFault("scaled", 5, 0.4, 3), ThrusterFault("stuck", 6, 0.08, 0)]
)
def test_the_fault_changes_the_realised_acceleration_exactly_as_recorded(dynamic_env, fault):
    env = dynamic_env
    scn = empty_space(seed=2, cw=False, fault=fault)
    _, info = env.reset(options={"scenario": scn})
    body, sim = scn.dynamics.body, env.sim
    command = np.array([0.3, 0.5, 0.5, 0.5, 0.6, 0.5, 0.0, 0.5])
    for step in range(6):
        fuel_before = info["fuel_kg"]
        _, _, _, _, info = env.step(command)
        assert np.array_equal(info["thrust"], fault.apply(command, step))  # what the thrusters gave
        burned = info["thrust"].sum() * sim.cubesat.mass_flow_per_thrust * sim.dt
        assert fuel_before - info["fuel_kg"] == pytest.approx(burned, rel=1e-12)  # fuel follows it
        # MuJoCo's acceleration at this state, thrust held, against rigid-body physics on the record.
        mujoco.mj_forward(env.model, env.data)
        mass, inertia = body_mass_properties(sim.cubesat, body.mass_scale, body.inertia_scale, info["fuel_kg"])
        assert info["mass"] == pytest.approx(mass, rel=1e-12)
        with_fault = _acceleration(env, fault, command, step, mass, inertia, body.com_offset)
        healthy = _acceleration(env, ThrusterFault(), command, step, mass, inertia, body.com_offset)
        assert np.allclose(env.data.qacc[0:3], with_fault[0], rtol=1e-7, atol=1e-7)
        assert np.allclose(env.data.qacc[3:6], with_fault[1], rtol=1e-7, atol=1e-7)
        if fault.active(step):
            assert np.linalg.norm(with_fault[0] - healthy[0]) > 0.1  # m/s^2: the fault shows
        else:
            assert np.array_equal(with_fault[0], healthy[0])


def test_a_stuck_thruster_fires_and_burns_fuel_when_nothing_is_commanded(dynamic_env):
    env = dynamic_env
    env.reset(options={"scenario": empty_space(cw=False, fault=ThrusterFault("stuck", 1, 0.07, 0))})
    v0 = com_velocity(env)
    _, _, _, _, info = env.step(np.zeros(8))
    assert info["thrust"][1] == 0.07 and np.linalg.norm(com_velocity(env) - v0) > 1e-3
    assert info["fuel_kg"] < env.sim.cubesat.fuel_mass


def test_the_camera_noise_has_the_drawn_statistics():
    rgb = np.full((64, 64, 3), 128, np.uint8)
    depth = np.full((64, 64), 3.0, np.float32)
    noisy, dropped = sense(rgb, depth, seed=5, frame=7, rgb_noise=0.02, dropout=0.15)
    assert (noisy.astype(float) - 128).std() == pytest.approx(0.02 * 255, rel=0.05)
    assert (dropped == 0).mean() == pytest.approx(0.15, abs=0.02) and set(np.unique(dropped)) == {0.0, 3.0}
    again = sense(rgb, depth, seed=5, frame=7, rgb_noise=0.02, dropout=0.15)
    assert np.array_equal(again[0], noisy) and np.array_equal(again[1], dropped)  # a function of (seed, frame)
    other = sense(rgb, depth, seed=5, frame=8, rgb_noise=0.02, dropout=0.15)
    assert not np.array_equal(other[0], noisy)


def _render_episode(seed: int, steps: int = 12, **sensing):
    """(scenario, frames) of a rendered episode; ``sensing`` changes the drawn camera."""
    env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=64)), DYNAMIC)
    scn = sample_scenario(seed, DYNAMIC)
    if sensing:
        scn = replace(scn, dynamics=replace(scn.dynamics, sensing=replace(scn.dynamics.sensing, **sensing)))
    frames = []
    obs, _ = env.reset(options={"scenario": scn})
    for t in range(steps):
        frames.append(
            (obs["image"].tobytes(), obs["depth"].tobytes(), obs["depth_low"].tobytes(), obs["state"].tobytes())
        )
        obs, _, terminated, truncated, _ = env.step(np.full(8, 0.3))
        if terminated or truncated:
            break
    env.close()
    return scn, frames


def test_same_seed_same_bytes_and_a_noisy_camera():
    scn, first = _render_episode(3)
    _, second = _render_episode(3)
    assert first == second
    _, other = _render_episode(4)
    assert first[0][0] != other[0][0]
    _, clean = _render_episode(3, rgb_noise=0.0, depth_dropout=0.0)  # the same scene, a perfect camera
    for noisy_frame, clean_frame in zip(first, clean):
        noisy, exact = (np.frombuffer(f[0], np.uint8).astype(float) for f in (noisy_frame, clean_frame))
        inside = (exact > 20) & (exact < 235)  # away from clipping
        assert (noisy - exact)[inside].std() == pytest.approx(0.02 * 255, rel=0.15)
        depth, exact_depth = (np.frombuffer(f[1], np.float32) for f in (noisy_frame, clean_frame))
        returns = exact_depth > 0
        dropped = (depth[returns] == 0).mean()
        assert dropped == pytest.approx(scn.dynamics.sensing.depth_dropout, abs=0.05)
        assert np.array_equal(depth[depth > 0], exact_depth[depth > 0])
        # depth_low is pooled from the depth before dropout: the scene's depth, not the sensor's holes.
        assert noisy_frame[2] == clean_frame[2] and noisy_frame[3] == clean_frame[3]


def test_a_kept_renderer_draws_what_a_fresh_one_draws():
    """The env keeps its textured GL context from one dynamic episode to the next (rebinding it to
    the new model): the frames are those of a renderer made for the episode."""
    env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=64)), DYNAMIC)
    env.reset(seed=3)
    renderer = env._renderer
    obs, _ = env.reset(seed=4)
    kept = [obs]
    for _ in range(5):
        kept.append(env.step(np.full(8, 0.3))[0])
    assert env._renderer is renderer  # kept, not made again
    env.close()
    _, fresh = _render_episode(4, steps=6)
    for obs, frame in zip(kept, fresh):
        assert obs["image"].tobytes() == frame[0] and obs["depth"].tobytes() == frame[1]


def test_eclipse_leaves_the_onboard_light_alone(dynamic_env):
    eclipse = next(s for s in range(50) if sample_scenario(s, DYNAMIC).dynamics.sensing.eclipse)
    dynamic_env.reset(seed=eclipse)
    model = dynamic_env.model
    sun, lamp = (mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_LIGHT, name) for name in ("sun", "onboard"))
    assert not model.light_diffuse[sun].any() and model.light_diffuse[lamp].min() > 0.0
    assert model.light_bodyid[lamp] == mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, BODY)  # moves with it


class Recorder(Pilot):
    """A learned pilot's view: it keeps what it is handed."""

    name, needs_images = "recorder", True

    def reset(self, task: Task) -> None:
        self.seen: list[dict] = []

    def act(self, obs: dict) -> np.ndarray:
        self.seen.append(obs)
        return np.zeros(8)


def test_a_learned_pilot_never_sees_the_privileged_poses():
    env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=64), max_steps=20), DYNAMIC)
    pilot = Recorder()
    fly_episode(env, pilot, seed=1)
    env.close()
    assert pilot.seen and all(set(obs) == {"state", "image"} for obs in pilot.seen)


def test_an_unavoiding_straight_flight_meets_the_debris():
    """The risky pilot flies straight to the goal, blind: with one piece of debris per episode its
    median closest approach is under 0.5 m (contact, mostly); with debris that only drifts it is not."""
    from orbitdata.fly.pilots.risky import RiskyPilot

    closest = {}
    for name, config in (
        ("aimed", DYNAMIC),
        ("drifting", replace(DYNAMIC, dynamic=replace(DYNAMIC.dynamic, intercept_prob=0.0))),
    ):
        env = CubeSatEnv(SimConfig(render=False), config)
        closest[name] = [fly_episode(env, RiskyPilot(), seed, n_obstacles=1).min_clearance.min() for seed in range(40)]
        env.close()
    assert np.median(closest["aimed"]) < 0.5
    assert np.median(closest["drifting"]) > 0.5
