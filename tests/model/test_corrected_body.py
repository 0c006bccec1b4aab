"""The world model's dynamics corrected by their misses over the pilot's history (``body=corrected``):
on a craft whose thrusts act through a response the probe does not know, the correction recovers
that response exactly, each episode its own, and the corrected rollout predicts what the uncorrected
one misses."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import planner_config, recorded
from orbitmodel.plan.corrected_body import CORRECTED, CorrectedLearnedDynamics
from orbitmodel.plan.dynamics import LearnedDynamics
from orbitmodel.plan.factory import build_pilot
from orbitmodel.probe.integrator import D_V, D_W, INCREMENT_DIM, integrate
from orbitmodel.probe.model import PhysicsProbe, load_probe

FRAMES, AHEAD = 40, 10


@pytest.fixture(scope="module", params=[1, 5], ids=["step1", "step5"])
def parts(request, probed_run):
    """A world model and an untrained probe of its run's probe's shape: it predicts zero increments
    whatever the latents (coasting), so a craft driven by ``[a, 1] @ C`` is exactly what it misses.
    The tiny run's model steps 1 frame per prediction; the flown recipe's 5, so the second is the
    tiny sizes stepping 5 frames (untrained: these tests read its rollouts, not their quality), with
    a probe that predicts every frame: frames and imagined steps then differ."""
    model = WorldModel.from_pretrained(probed_run)
    config, _ = load_probe(probed_run, "latent")
    if request.param > 1:
        torch.manual_seed(0)
        model = WorldModel(replace(model.config, frame_step=request.param)).eval()
        config = replace(config, substeps=request.param, action_dim=config.action_dim and 8 * request.param)
    assert model.config.frame_step == config.substeps == request.param
    return model, PhysicsProbe(config).eval()


def start_state() -> torch.Tensor:
    state = torch.zeros(16)
    state[6], state[10] = 1.0, 1.0  # rot6d: the identity's first two columns
    state[15] = 1.0  # a full tank
    return state


def driven(C: torch.Tensor, state: torch.Tensor, actions: torch.Tensor, dt: float) -> torch.Tensor:
    """The states (n, 16) after each of ``actions`` (n, 8): coasting, plus [a, 1] @ C per frame."""
    inc = torch.zeros(1, len(actions), INCREMENT_DIM)
    inc[0, :, D_V.start : D_W.stop] = torch.cat([actions, torch.ones(len(actions), 1)], -1) @ C
    return integrate(state[None], inc, dt, coasting=True)[0]


def flown(dynamics, C, rng, frames=FRAMES + 5) -> torch.Tensor:
    """``dynamics`` after observing ``frames`` frames of the craft ``C`` drives under random
    thrusts (random latents: this probe reads none); the last state observed."""
    state, previous = start_state(), None
    D = dynamics.model.config.latent_dim
    for frame in range(frames):
        if frame:
            previous = rng.uniform(0, 0.3, 8).astype(np.float32)
            state = driven(C, state, torch.from_numpy(previous)[None], dynamics.probe.config.dt)[0]
        dynamics.push(torch.as_tensor(rng.normal(size=D), dtype=torch.float32), previous, {"state": state.numpy()})
    return state


def craft(seed: int) -> torch.Tensor:
    """A response (9, 6): per thruster and a constant (a stuck thruster), velocity and rate changes per frame."""
    return torch.as_tensor(np.random.default_rng(seed).normal(0, 0.05, (9, 6)), dtype=torch.float32)


def test_the_correction_recovers_the_response_the_probe_misses_and_the_rollout_then_predicts_it(parts):
    model, probe = parts
    C = craft(1)
    rng = np.random.default_rng(0)
    dynamics = CorrectedLearnedDynamics(model, probe, fit_frames=FRAMES, ridge=1e-9)
    assert torch.equal(dynamics.correction(), torch.zeros(1, 9, 6))  # nothing seen: the world model's own
    state = flown(dynamics, C, rng)
    torch.testing.assert_close(dynamics.correction()[0], C, atol=2e-4, rtol=1e-3)
    plans = torch.as_tensor(rng.uniform(0, 0.3, (3, AHEAD, 8)), dtype=torch.float32)
    truth = torch.stack([driven(C, state, p, probe.config.dt) for p in plans])
    corrected = dynamics.rollout(state, plans)
    torch.testing.assert_close(corrected, truth, atol=2e-3, rtol=1e-3)
    plain = LearnedDynamics(model, probe)
    plain.push(torch.zeros(model.config.latent_dim), None)
    missed = (plain.rollout(state, plans) - truth).abs().amax()
    assert missed > 50 * (corrected - truth).abs().amax()


def test_each_episode_of_a_batch_is_corrected_by_its_own_history_and_a_gap_starts_it_again(parts):
    model, probe = parts
    lead = CorrectedLearnedDynamics(model, probe, fit_frames=FRAMES, ridge=1e-9)
    crafts = [craft(2), craft(3)]
    members, starts = [lead.fork(), lead.fork()], []
    for i, (member, C) in enumerate(zip(members, crafts)):
        starts.append(flown(member, C, np.random.default_rng(10 + i)))
    plans = [torch.as_tensor(np.random.default_rng(20).uniform(0, 0.3, (2, AHEAD, 8)), dtype=torch.float32)] * 2
    together = CorrectedLearnedDynamics.rollout_many(members, starts, plans)
    for member, C, state, plan, states in zip(members, crafts, starts, plans, together):
        truth = torch.stack([driven(C, state, p, probe.config.dt) for p in plan])
        torch.testing.assert_close(states, truth, atol=2e-3, rtol=1e-3)
        torch.testing.assert_close(states, member.rollout(state, plan))
    members[0].push(torch.zeros(model.config.latent_dim), None, {"state": starts[0].numpy()})  # a gap
    assert torch.equal(members[0].correction(), torch.zeros(1, 9, 6))
    assert not torch.equal(members[1].correction(), torch.zeros(1, 9, 6))


class StepBiased(PhysicsProbe):
    """A probe whose increments drift with the imagined step: ``bias[j]`` (6,) is added to the
    velocity and rate increments of every frame of the j-th step it reads (the last for later ones)."""

    bias = torch.zeros(1, 6)

    def step_increments(self, z_future, z_last=None, actions=None):
        inc = super().step_increments(z_future, z_last, actions).clone()
        s = inc.shape[1] // z_future.shape[1]
        for j in range(z_future.shape[1]):
            inc[:, j * s : (j + 1) * s, CORRECTED] += self.bias[min(j, len(self.bias) - 1)]
        return inc


def test_a_correction_per_imagined_step_undoes_misses_that_grow_with_the_step(parts):
    model, plain_probe = parts
    probe = StepBiased(plain_probe.config).eval()
    probe.load_state_dict(plain_probe.state_dict())
    steps = 3
    probe.bias = torch.as_tensor(np.random.default_rng(4).normal(0, 0.02, (steps, 6)), dtype=torch.float32)
    C = craft(5)
    dynamics = CorrectedLearnedDynamics(model, probe, fit_frames=FRAMES, ridge=1e-9, fit_steps=steps)
    s = dynamics.step
    state = flown(dynamics, C, np.random.default_rng(6), frames=FRAMES + (dynamics.history + steps) * s)
    fitted = dynamics.correction()  # (steps, 9, 6): step j's bias row absorbs the probe's drift there
    for j in range(steps):
        want = C.clone()
        want[-1] -= probe.bias[j]
        torch.testing.assert_close(fitted[j], want, atol=2e-4, rtol=1e-3)
    rng = np.random.default_rng(7)
    plans = torch.as_tensor(rng.uniform(0, 0.3, (3, (steps + 1) * s, 8)), dtype=torch.float32)  # past the last fit
    truth = torch.stack([driven(C, state, p, probe.config.dt) for p in plans])
    corrected = dynamics.rollout(state, plans)
    torch.testing.assert_close(corrected, truth, atol=2e-3, rtol=1e-3)
    first_only = CorrectedLearnedDynamics(model, probe, fit_frames=FRAMES, ridge=1e-9)
    flown(first_only, C, np.random.default_rng(6), frames=FRAMES + (dynamics.history + steps) * s)
    assert (first_only.rollout(state, plans) - truth).abs().amax() > 20 * (corrected - truth).abs().amax()


def test_the_pilots_that_plan_with_the_world_model_fly_it_and_the_others_are_told(probed_run):
    config = planner_config("cpu", body="corrected", fit_frames=20, horizon=10, samples=4)
    pilot, _ = build_pilot("planner", probed_run, config)
    assert isinstance(pilot.dynamics, CorrectedLearnedDynamics) and pilot.dynamics.fit_frames == 20
    oracle, _ = build_pilot(
        "oracle-learned-dyn", probed_run, planner_config("cpu", obstacle_motion="true", body="corrected")
    )
    assert isinstance(oracle.dynamics, CorrectedLearnedDynamics)
    assert recorded(config)["body"] == "corrected"
    assert (recorded(config)["fit_frames"], recorded(config)["fit_ridge"], recorded(config)["fit_steps"]) == (
        20,
        1e-5,
        1,
    )
    stepped, _ = build_pilot("planner", probed_run, planner_config("cpu", body="corrected", fit_steps=3, horizon=10))
    assert stepped.dynamics.fit_steps == 3
    with pytest.raises(ValueError, match="add --set body=corrected"):
        planner_config("cpu", body="fitted", fit_steps=3)
    with pytest.raises(ValueError, match="fly planner or oracle-learned-dyn"):
        build_pilot("oracle-true", None, planner_config("cpu", obstacle_motion="true", body="corrected"))


def test_each_step_is_imagined_from_the_context_latents_before_it_and_the_thrusts_flown_through_it(parts):
    model, probe = parts

    class Watched:  # the world model, keeping what each rollout is handed
        def __init__(self):
            self.calls = []

        def __getattr__(self, name):
            return getattr(model, name)

        def rollout(self, z, actions, history):
            self.calls.append((z.clone(), actions.clone(), history))
            return model.rollout(z, actions, history)

    dynamics = CorrectedLearnedDynamics(model, probe, fit_frames=FRAMES)
    watched = dynamics.model = Watched()
    s, m, D = dynamics.step, dynamics.history, model.config.latent_dim
    latents = [torch.full((D,), float(j)) for j in range(m * s + 2)]
    thrusts = [np.full(8, j / 100, np.float32) for j in range(m * s + 2)]  # thrusts[j] led to frame j
    for j, z in enumerate(latents):
        dynamics.push(z, thrusts[j] if j else None, {"state": start_state().numpy()})
    assert len(watched.calls) == 2  # one step ended at each frame from m s on
    for t, (z, actions, history) in zip((m * s, m * s + 1), watched.calls):
        first = t - m * s
        torch.testing.assert_close(z[0], torch.stack(latents[first:t:s]))  # frames t - m s .. t - s
        flown = torch.from_numpy(np.stack(thrusts[first + 1 : t + 1]))  # the thrusts into frames after the first
        torch.testing.assert_close(actions[0], flown.reshape(m, 8 * s))
        assert history == m


def test_every_imagined_step_is_fitted_to_the_newest_step_from_its_own_context_once(parts):
    model, probe = parts
    calls = []

    class Watched:
        def __getattr__(self, name):
            return getattr(model, name)

        def rollout(self, z, actions, history):
            calls.append((z.clone(), actions.clone()))
            return model.rollout(z, actions, history)

    dynamics = CorrectedLearnedDynamics(model, probe, fit_frames=FRAMES, fit_steps=2)
    dynamics.model = Watched()
    s, m, D = dynamics.step, dynamics.history, model.config.latent_dim
    frames = (m + 1) * s + 3
    latents = [torch.full((D,), float(j)) for j in range(frames)]
    thrusts = [np.full(8, j / 100, np.float32) for j in range(frames)]  # thrusts[j] led to frame j
    for j, z in enumerate(latents):
        dynamics.push(z, thrusts[j] if j else None, {"state": start_state().numpy()})
    # the first step is fitted at every frame from m s on, the second from (m + 1) s on: once each
    assert [len(sums) for sums in dynamics._sums] == [frames - m * s, frames - (m + 1) * s]
    z, actions = calls[-1]
    t = frames - 1
    assert z.shape[0] == 2  # one row per imagined step, each ending at frame t
    for row, j in enumerate((1, 2)):
        first = t - (m + j - 1) * s
        torch.testing.assert_close(z[row], torch.stack(latents[first : t - j * s + 1 : s]))
        flown = torch.from_numpy(np.stack(thrusts[first + 1 : t + 1])).reshape(m - 1 + j, 8 * s)
        torch.testing.assert_close(actions[row, : m - 1 + j], flown)
