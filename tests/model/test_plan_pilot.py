"""The planning pilots: never told the obstacles, nothing invalid reaches the simulator, they fly."""

from __future__ import annotations

import dataclasses
import gc
import inspect

import numpy as np
import pytest
import torch

from orbitdata.fly.pilot import Task
from orbitdata.fly.rollout import fly_episode
from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.seeding import grid_seed
from orbitdata.sim.config import CameraConfig, SimConfig
from orbitdata.sim.env import CubeSatEnv
from orbitmodel.config import get_preset
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import PlannerConfig
from orbitmodel.plan.dynamics import LearnedDynamics, RigidBodyDynamics
from orbitmodel.plan.factory import PredictedDepth, sensor_depth
from orbitmodel.plan.mppi import MPPIConfig
from orbitmodel.plan.obstacles import Camera
from orbitmodel.plan.pilot import OraclePilot, PlannerPilot, Variant
from orbitmodel.probe.model import PhysicsProbe
from orbitmodel.probe.train import probe_config

torch.set_num_threads(1)
SIM = SimConfig(camera=CameraConfig(image_size=64), max_steps=8)
SMALL = PlannerConfig(mppi=MPPIConfig(samples=8, horizon=5))
# (16,) state: at the origin, at rest, identity attitude (rot6d), full tank
AT_REST = np.r_[np.zeros(6), 1, 0, 0, 1, 0, 0, np.zeros(3), 1].astype(np.float32)


class StandInProbe:
    """The probe's API for a per-frame world model: the state held, nudged by the latents."""

    def per_frame(
        self,
        z_future: torch.Tensor,
        state0: torch.Tensor,
        z_last: torch.Tensor,
        frame_step: int,
        actions: torch.Tensor | None = None,
    ):
        assert frame_step == 1
        return state0[:, None].expand(-1, z_future.shape[1], -1) + 0.01 * z_future[..., :1]


stand_in_probe = StandInProbe()


def untrained_probe(model: WorldModel) -> PhysicsProbe:
    """A real probe for ``model`` (the tiny preset's recipe, untrained, seeded), as the planner reads it."""
    torch.manual_seed(0)
    config = probe_config(get_preset("tiny").probe, "latent", model.config.latent_dim, model.config.frame_step)
    return PhysicsProbe(config).eval()


def learned_planner(config: PlannerConfig = SMALL, model: WorldModel | None = None) -> PlannerPilot:
    model = model or WorldModel(get_preset("tiny").model).eval()
    return PlannerPilot(
        Variant.PLANNER,
        LearnedDynamics(model, untrained_probe(model)),
        PredictedDepth(model),
        Camera.from_sim(SIM),
        config,
        SIM,
    )


def sensor_planner(config: PlannerConfig = SMALL) -> PlannerPilot:
    return PlannerPilot(
        Variant.ORACLE_TRUE_DYN_SENSOR, RigidBodyDynamics(SIM), sensor_depth, Camera.from_sim(SIM), config, SIM
    )


def reachable(root, kinds: tuple[type, ...], limit: int = 200_000) -> list:
    """Objects of ``kinds`` reachable from ``root`` through references (a breadth-first walk).
    Module namespaces are not entered: a method's globals lead to every imported module, and
    other test modules hold scenes of their own, which no pilot was given."""
    import sys

    namespaces = {id(vars(m)) for m in list(sys.modules.values()) if m is not None and hasattr(m, "__dict__")}
    seen, queue, found = {id(root)} | namespaces, [root], []
    skip = (type, type(inspect), torch.Tensor, np.ndarray, str, bytes)
    while queue and len(seen) < limit:
        obj = queue.pop()
        if isinstance(obj, kinds):
            found.append(obj)
        for ref in gc.get_referents(obj):
            if id(ref) not in seen and not isinstance(ref, skip):
                seen.add(id(ref))
                queue.append(ref)
    if queue:  # stopped at the limit: an unfinished walk proves nothing
        pytest.fail(f"the walk from {type(root).__name__} reached {limit} objects unfinished; raise the limit")
    return found


class Spy:
    """Wraps a pilot: records what reset and act were given."""

    def __init__(self, pilot):
        self.pilot, self.resets, self.observations = pilot, [], []
        self.name, self.privileged, self.needs_images = pilot.name, pilot.privileged, pilot.needs_images
        self.sees_depth = pilot.sees_depth

    def reset(self, *args, **kwargs):
        self.resets.append((args, kwargs))
        return self.pilot.reset(*args, **kwargs)

    def act(self, obs):
        self.observations.append(set(obs))
        return self.pilot.act(obs)

    def metadata(self):
        return self.pilot.metadata()


@pytest.mark.parametrize("make", [learned_planner, sensor_planner], ids=["planner", "sensor"])
def test_the_planner_pilot_never_receives_the_obstacles(make):
    """The planner is handed nothing but the task; the sensor oracle, which plans with the true body,
    is handed the scenario for that body and keeps nothing of its obstacles."""
    pilot = make()
    sensor = pilot.variant == Variant.ORACLE_TRUE_DYN_SENSOR
    assert pilot.privileged is sensor and type(pilot).privileged is False
    spy = Spy(pilot)
    env = CubeSatEnv(SIM)
    result = fly_episode(env, spy, grid_seed(0, 3, 1.0, 0), 3, 1.0)
    env.close()
    assert len(result.scenario.obstacles) == 3 and result.length > 1
    ((args, kwargs),) = spy.resets
    assert len(args) == 1 and isinstance(args[0], Task)
    assert list(kwargs) == (["scenario"] if sensor else [])
    if not sensor:
        with pytest.raises(ValueError, match="no ground truth"):
            pilot.reset(args[0], scenario=result.scenario)
    rendered = {"depth", "depth_low"} if sensor else set()
    assert all(keys == {"state", "image"} | rendered for keys in spy.observations)  # the rendered depth: sensor only
    del result, env, spy
    gc.collect()
    assert reachable(pilot, (Scenario, Obstacle)) == []


def test_the_spy_would_see_an_oracles_obstacles():
    sim = dataclasses.replace(SIM, render=False)
    oracle = OraclePilot(Variant.ORACLE_TRUE, RigidBodyDynamics(sim), None, Camera.from_sim(sim), SMALL, sim)
    assert oracle.privileged is True and oracle.needs_images is False
    env = CubeSatEnv(sim)
    fly_episode(env, oracle, grid_seed(0, 3, 1.0, 0), 3, 1.0)
    env.close()
    assert len(reachable(oracle, (Obstacle,))) == 3
    with pytest.raises(ValueError, match="scenario"):
        oracle.reset(Task((1.0, 0, 0), 0.5, (0.0, 0, 0), 0))


def test_variants_pick_the_right_class():
    with pytest.raises(ValueError):
        PlannerPilot(Variant.ORACLE_TRUE, RigidBodyDynamics(SIM), None, Camera.from_sim(SIM), SMALL, SIM)
    with pytest.raises(ValueError):
        OraclePilot(Variant.PLANNER, RigidBodyDynamics(SIM), sensor_depth, Camera.from_sim(SIM), SMALL, SIM)


def test_nan_and_out_of_range_thrusts_never_reach_the_simulator():
    pilot = sensor_planner()
    pilot.reset(Task((5.0, 0, 0), 0.5, (0.0, 0, 0), 0))

    update = pilot.mppi.update

    def broken(candidates, costs):  # a planner gone wrong: NaN and 1.5
        result = update(candidates, costs)
        pilot.mppi.nominal = torch.tensor([[float("nan"), 1.5, -0.2, 0.5, 0, 0, 0, 0]] * 5)
        return result

    pilot.mppi.update = broken
    obs = {"state": AT_REST, "depth_low": np.full((16, 16), 50.1, np.float32)}
    action = pilot.act(obs)
    assert np.isfinite(action).all() and action.min() >= 0 and action.max() <= 1
    assert action.tolist() == [0, 1, 0, 0.5, 0, 0, 0, 0]
    meta = pilot.metadata()
    assert meta["nonfinite_actions"] == 1 and meta["clipped_actions"] == 1


@pytest.mark.parametrize("support, expected", [(0, 10), (1, 9)])
def test_the_pilot_plans_around_supported_depth_cells_only(support, expected):
    pilot = sensor_planner(dataclasses.replace(SMALL, support=support))
    pilot.reset(Task((5.0, 0, 0), 0.5, (0.0, 0, 0), 0))
    depth = np.full((16, 16), 50.1, np.float32)
    depth[6:9, 6:9] = 3.0  # a surface ahead: nine cells
    depth[2, 12] = 4.0  # one stray cell, no neighbour near its depth
    obs = {"state": AT_REST, "depth_low": depth}
    pilot.act(obs)
    assert pilot.cloud_sizes == [expected]
    assert pilot.metadata()["points_median"] == expected


def test_an_episode_is_a_function_of_its_seed():
    runs, model = [], WorldModel(get_preset("tiny").model).eval()
    for _ in range(2):
        pilot = learned_planner(model=model)
        env = CubeSatEnv(SIM)
        runs.append(fly_episode(env, pilot, grid_seed(0, 1, 2.0, 0), 1, 2.0).actions)
        env.close()
    assert np.array_equal(runs[0], runs[1]) and np.abs(runs[0]).sum() > 0


def test_the_true_oracle_flies_an_easy_episode_to_the_goal():
    sim = SimConfig(render=False)
    oracle = OraclePilot(Variant.ORACLE_TRUE, RigidBodyDynamics(sim), None, Camera.from_sim(sim), PlannerConfig(), sim)
    env = CubeSatEnv(sim)
    result = fly_episode(env, oracle, grid_seed(0, 1, 2.0, 1), 1, 2.0)  # the obstacle lies off the line
    env.close()
    assert result.outcome == "success", result.outcome
    meta = result.pilot_info
    assert meta["replans"] == result.length - 1 and meta["nonfinite_actions"] == 0 and meta["clipped_actions"] == 0


def test_the_dynamics_and_the_depth_head_share_one_encoder_pass_per_frame():
    from orbitmodel.plan.frames import FrameEncoder

    model = WorldModel(get_preset("tiny").model).eval()
    calls = []
    model.encoder.register_forward_hook(lambda *_: calls.append(1))
    frames = FrameEncoder(model)
    dyn = LearnedDynamics(model, stand_in_probe, frames=frames)
    depth = PredictedDepth(model, frames=frames)
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (64, 64, 3), dtype=np.uint8)
    state = rng.normal(size=16).astype(np.float32)
    dyn.observe({"image": image, "state": state}, None)
    got = depth({"image": image})
    assert len(calls) == 1  # one ViT pass for the latent and the depth map
    with torch.no_grad():  # the same numbers as encoding the frame for each reading
        x = torch.from_numpy(image).permute(2, 0, 1)[None, None]
        assert torch.equal(dyn._z[-1], model.encode(x, torch.from_numpy(state)[None, None])[0, 0])
        assert np.array_equal(got, model.predict_depth(x)[0, 0].numpy())
    image[:8] = 0  # the same buffer holding a new frame is encoded again
    depth({"image": image})
    assert len(calls) == 4  # + the two reference passes above + this one


@pytest.mark.parametrize(
    "bad",
    [
        dict(support=9),
        dict(support=-1),
        dict(memory_frames=0),
        dict(replan_every=0),
        dict(depth_head="best head"),
        dict(noise="colour"),
    ],
)
def test_a_planner_config_out_of_range_is_refused_by_name(bad):
    (key,) = bad
    with pytest.raises(ValueError, match=key):
        PlannerConfig(**bad)


def test_build_pilot_names_the_pilots_and_the_config_it_takes():
    from orbitmodel.plan.factory import build_pilot

    with pytest.raises(ValueError, match=r"pilot 'plan': give one of planner, oracle-true"):
        build_pilot("plan")
    with pytest.raises(ValueError, match=r"config is a str: give a PlannerConfig, such as planner_config\('cpu'\)"):
        build_pilot("oracle-true", None, "cpu")
