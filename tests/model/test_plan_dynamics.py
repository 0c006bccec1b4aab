"""The planner's dynamics: the torch rigid body against MuJoCo, and the learned rollout's plumbing."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from orbitdata.scenario.spec import Scenario
from orbitdata.sim.config import SimConfig
from orbitdata.sim.env import CubeSatEnv
from orbitdata.state import so3_log
from orbitmodel.config import get_preset
from orbitmodel.kinematics import matrix_to_rot6d, rot6d_to_matrix, so3_exp
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.dynamics import LearnedDynamics, RigidBodyDynamics

torch.set_num_threads(1)


def _scenario() -> Scenario:
    q = np.array([0.9, 0.1, 0.3, -0.2])
    return Scenario(
        obstacles=(),
        goal=(10.0, 0.0, 0.0),
        initial_velocity=(1.0, 0.3, -0.2),
        initial_quat=tuple(q / np.linalg.norm(q)),
    )


def fly_mujoco(actions: np.ndarray, sim: SimConfig) -> tuple[np.ndarray, np.ndarray]:
    env = CubeSatEnv(sim)
    obs, _ = env.reset(options={"scenario": _scenario()})
    start = obs["state"]
    states = []
    for a in actions:
        obs, *_ = env.step(a)
        states.append(obs["state"])
    env.close()
    return start, np.array(states)


def errors(pred: np.ndarray, true: np.ndarray) -> dict:
    Rp, Rt = rot6d_to_matrix(torch.tensor(pred[:, 6:12])).numpy(), rot6d_to_matrix(torch.tensor(true[:, 6:12])).numpy()
    angle = max(np.linalg.norm(so3_log(a.T @ b)) for a, b in zip(Rp, Rt))
    return {
        "p": np.abs(pred[:, 0:3] - true[:, 0:3]).max(),
        "v": np.abs(pred[:, 3:6] - true[:, 3:6]).max(),
        "angle": angle,
        "w": np.abs(pred[:, 12:15] - true[:, 12:15]).max(),
        "fuel": np.abs(pred[:, 15] - true[:, 15]).max(),
    }


def random_thrusts(rng: np.random.Generator, steps: int, high: float) -> np.ndarray:
    return rng.uniform(0, high, size=(steps, 8)) * (rng.uniform(size=(steps, 8)) < 0.5)


def test_rigid_body_with_the_simulators_substeps_is_mujoco():
    sim = SimConfig(render=False)
    actions = random_thrusts(np.random.default_rng(0), 25, 1.0)  # up to ~15 rad/s spins
    start, true = fly_mujoco(actions, sim)
    pred = RigidBodyDynamics(sim, substeps=sim.substeps).rollout(
        torch.tensor(start), torch.tensor(actions, dtype=torch.float32)[None]
    )[0]
    e = errors(pred.numpy(), true)
    # float32 against MuJoCo's float64: the same scheme, rounding only.
    assert e["p"] < 1e-4 and e["v"] < 1e-4 and e["angle"] < 2e-3 and e["w"] < 1e-4 and e["fuel"] < 1e-5, e


def test_rigid_body_one_substep_is_close_to_mujoco():
    # One substep folds the simulator's 8 into closed-form increments. Measured over 1 s of
    # flight-like thrusts in [0, 0.3] (bodies turning at up to ~5 rad/s): p 1.2 mm, v 4 mm/s,
    # 3 mrad (seed 0); the bounds leave a 2-4x margin. The planner's collision margin is 0.4 m.
    sim = SimConfig(render=False)
    actions = random_thrusts(np.random.default_rng(0), 25, 0.3)
    start, true = fly_mujoco(actions, sim)
    pred = RigidBodyDynamics(sim, substeps=1).rollout(
        torch.tensor(start), torch.tensor(actions, dtype=torch.float32)[None]
    )[0]
    e = errors(pred.numpy(), true)
    assert e["p"] < 5e-3 and e["v"] < 2e-2 and e["angle"] < 1e-2 and e["w"] < 1e-4 and e["fuel"] < 1e-5, e


def test_rigid_body_empties_the_tank_as_the_simulator_does():
    import dataclasses

    # A 3 g tank, the top ring at full thrust (29 g/s): two full steps, then a third scaled to
    # the 0.67 step of fuel left; the env ends the episode there, the model coasts on.
    sim = dataclasses.replace(
        SimConfig(render=False), cubesat=dataclasses.replace(SimConfig().cubesat, fuel_mass=0.003)
    )
    actions = np.tile([1.0, 1, 1, 1, 0, 0, 0, 0], (6, 1))
    start, true = fly_mujoco(actions[:3], sim)
    pred = RigidBodyDynamics(sim, substeps=sim.substeps).rollout(
        torch.tensor(start), torch.tensor(actions, dtype=torch.float32)[None]
    )[0]
    e = errors(pred[:3].numpy(), true)
    assert e["v"] < 1e-4 and e["fuel"] < 1e-5, e
    assert true[2, 15] == 0 and pred[2, 15] == 0
    dv = (pred[1:, 3:6] - pred[:-1, 3:6]).norm(dim=-1)  # (5,) m/s per step
    assert 0.5 < dv[1] / dv[0] < 0.8 and dv[2:].max() < 1e-6  # the partial step, then coasting


def test_rotation_helpers():
    g = torch.Generator().manual_seed(0)
    axis = torch.nn.functional.normalize(torch.randn(100, 3, generator=g), dim=-1)
    angle = torch.cat([torch.rand(50, generator=g) * 3.0, torch.rand(50, generator=g) * 1e-3])  # large and tiny
    phi = axis * angle[:, None]
    R = so3_exp(phi)
    assert torch.allclose(R @ R.transpose(-1, -2), torch.eye(3).expand(100, 3, 3), atol=1e-5)
    logs = np.stack([so3_log(r) for r in R.double().numpy()])
    assert np.allclose(logs, phi.numpy(), atol=1e-4)
    assert torch.allclose(rot6d_to_matrix(matrix_to_rot6d(R)), R, atol=1e-5)


class SpyModel(WorldModel):
    """The tiny world model, recording what its rollout was given."""

    def rollout(self, z_context, actions, history=None):
        self.seen = (z_context.clone(), actions.clone())
        self.history_seen = history
        return super().rollout(z_context, actions, history)


class StandInProbe:
    """The probe's API (``per_frame``): the initial state held, shifted by the latent mean, at each
    latent, and interpolated between them."""

    def per_frame(
        self,
        z_future: torch.Tensor,
        state0: torch.Tensor,
        z_last: torch.Tensor,
        frame_step: int,
        actions: torch.Tensor | None = None,
    ):
        from orbitmodel.kinematics import interpolate_frames

        self.actions = actions  # what the planner hands a probe that reads thrusts
        states = state0[:, None].expand(-1, z_future.shape[1], -1) + z_future.mean(-1, keepdim=True)  # (B, n, 16)
        return states if frame_step == 1 else interpolate_frames(state0, states, frame_step)


stand_in_probe = StandInProbe()


def test_learned_dynamics_keeps_the_context_and_the_actions_between_frames():
    model = SpyModel(get_preset("tiny").model).eval()  # history 4
    dyn = LearnedDynamics(model, stand_in_probe)
    rng = np.random.default_rng(0)
    taken = []
    for t in range(6):
        obs = {"image": rng.integers(0, 255, (64, 64, 3), dtype=np.uint8), "state": np.zeros(16, np.float32)}
        previous = None if t == 0 else taken[-1]
        dyn.observe(obs, previous)
        taken.append(rng.uniform(0, 1, 8).astype(np.float32))
    plan = torch.rand(5, 7, 8)  # K=5 candidates, H=7
    states = dyn.rollout(torch.zeros(16), plan)
    assert states.shape == (5, 7, 16) and torch.isfinite(states).all()
    z_context, actions = model.seen
    assert z_context.shape[:2] == (5, 4)  # the last `history` frames, one copy per candidate
    assert actions.shape == (5, 3 + 7, 8)
    # the 3 actions taken between the 4 context frames (frames 2..5), then the plan
    assert torch.allclose(actions[0, :3], torch.tensor(np.array(taken[2:5])))
    assert torch.equal(actions[:, 3:], plan)
    assert model.history_seen == 4


def test_learned_dynamics_with_a_shorter_history_keeps_fewer_frames():
    model = SpyModel(get_preset("tiny").model).eval()  # history 4
    dyn = LearnedDynamics(model, stand_in_probe, history=2)
    rng = np.random.default_rng(0)
    for t in range(5):
        obs = {"image": rng.integers(0, 255, (64, 64, 3), dtype=np.uint8), "state": np.zeros(16, np.float32)}
        dyn.observe(obs, None if t == 0 else rng.uniform(0, 1, 8).astype(np.float32))
    dyn.rollout(torch.zeros(16), torch.rand(3, 5, 8))
    z_context, actions = model.seen
    assert z_context.shape[:2] == (3, 2) and actions.shape == (3, 1 + 5, 8) and model.history_seen == 2
    with pytest.raises(ValueError, match="at most 4 latents"):
        LearnedDynamics(model, stand_in_probe, history=5)


def test_learned_dynamics_starts_with_one_frame_and_forgets_on_reset():
    model = SpyModel(get_preset("tiny").model).eval()
    dyn = LearnedDynamics(model, stand_in_probe)
    with pytest.raises(RuntimeError, match=r"observe\(\) a frame before rollout"):
        dyn.rollout(torch.zeros(16), torch.rand(2, 3, 8))
    dyn.observe({"image": np.zeros((64, 64, 3), np.uint8), "state": np.zeros(16, np.float32)}, None)
    assert dyn.rollout(torch.zeros(16), torch.rand(2, 3, 8)).shape == (2, 3, 16)
    assert model.seen[0].shape[1] == 1 and model.seen[1].shape[1] == 3
    dyn.reset()
    with pytest.raises(RuntimeError, match=r"observe\(\) a frame before rollout"):
        dyn.rollout(torch.zeros(16), torch.rand(2, 3, 8))


def test_learned_dynamics_with_a_frame_step_sees_every_step_th_frame_and_grouped_actions():
    model = SpyModel(get_preset("tiny").with_model(frame_step=3).model).eval()
    dyn = LearnedDynamics(model, stand_in_probe, history=3)
    rng = np.random.default_rng(0)
    taken, latents = [], []
    for t in range(9):  # frames 0..8; the context is frames 2, 5, 8
        obs = {"image": rng.integers(0, 255, (64, 64, 3), dtype=np.uint8), "state": np.zeros(16, np.float32)}
        dyn.observe(obs, None if t == 0 else taken[-1])
        with torch.no_grad():
            latents.append(
                model.encode(torch.from_numpy(obs["image"]).permute(2, 0, 1)[None, None], torch.zeros(1, 1, 16))[0, 0]
            )
        taken.append(rng.uniform(0, 1, 8).astype(np.float32))
    plan = torch.rand(4, 6, 8)  # H = 6 frames = 2 predictor steps
    states = dyn.rollout(torch.zeros(16), plan)
    assert states.shape == (4, 6, 16)
    z_context, actions = model.seen
    assert torch.allclose(z_context[0], torch.stack([latents[2], latents[5], latents[8]]), atol=1e-6)
    assert actions.shape == (4, 2 + 2, 24)  # 2 steps between the context frames, then the plan's 2
    assert torch.allclose(actions[0, 0], torch.tensor(np.concatenate(taken[2:5])))  # thrusts of frames 2, 3, 4
    assert torch.allclose(actions[0, 1], torch.tensor(np.concatenate(taken[5:8])))
    assert torch.equal(actions[:, 2:], plan.reshape(4, 2, 24))
    assert torch.equal(stand_in_probe.actions, plan.reshape(4, 2, 24))  # the probe reads the planned steps' thrusts
    with pytest.raises(ValueError, match="multiple of 3"):
        dyn.rollout(torch.zeros(16), torch.rand(4, 5, 8))
    # at the start of an episode the context holds the frames one step apart that exist: frame 3, not 1..3
    dyn.reset()
    for t in range(4):
        dyn.observe(
            {"image": np.zeros((64, 64, 3), np.uint8), "state": np.zeros(16, np.float32)},
            None if t == 0 else taken[t - 1],
        )
    dyn.rollout(torch.zeros(16), plan)
    assert model.seen[0].shape[1] == 2 and model.seen[1].shape[1] == 1 + 2  # frames 0 and 3


def test_interpolated_frames_pass_through_the_predicted_states():
    from orbitmodel.kinematics import interpolate_frames

    R = so3_exp(torch.tensor([[0.0, 0.0, 0.3], [0.0, 0.0, 0.6]]))
    state0 = torch.zeros(1, 16)
    state0[0, 6:12] = matrix_to_rot6d(torch.eye(3))
    states = torch.zeros(1, 2, 16)
    states[0, :, 0] = torch.tensor([1.0, 3.0])  # x at frames t+2 and t+4
    states[0, :, 6:12] = matrix_to_rot6d(R)
    out = interpolate_frames(state0, states, 2)  # (1, 4, 16) at t+1..t+4
    assert torch.allclose(out[0, :, 0], torch.tensor([0.5, 1.0, 2.0, 3.0]))
    assert torch.allclose(out[0, 1::2], states[0], atol=1e-6)  # the predicted states unchanged
    R_mid = rot6d_to_matrix(out[0, 0, 6:12])
    assert torch.allclose(R_mid @ R_mid.T, torch.eye(3), atol=1e-5)  # still a rotation
    assert abs(float(so3_log_angle(R_mid)) - 0.15) < 0.01  # about half of the first step's turn


def so3_log_angle(R: torch.Tensor) -> torch.Tensor:
    return torch.arccos(((R.diagonal().sum() - 1) / 2).clamp(-1, 1))
