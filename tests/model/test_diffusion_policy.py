"""The Diffusion Policy's networks, schedules, normalisation and EMA, on synthetic tensors."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from orbitdata.state import make_state
from orbitmodel.baselines.diffusion.config import PolicyConfig, get_policy_preset
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy, denoise, ema_decay, goal_in_body, make_schedulers
from orbitmodel.baselines.diffusion.sampling import PolicySampling
from orbitmodel.baselines.diffusion.unet import ConditionalUnet1D

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def config() -> PolicyConfig:
    return get_policy_preset("tiny").model


def batch(config: PolicyConfig, B: int = 3, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    To, S = config.n_obs_steps, config.image_size
    states = torch.randn(B, To, 16, generator=g)
    states[..., 6:12] = torch.tensor([1.0, 0, 0, 1, 0, 0])  # identity rotation
    return {
        "images": torch.randint(0, 256, (B, To, 3, S, S), generator=g, dtype=torch.uint8),
        "states": states,
        "goal": torch.randn(B, 3, generator=g) * 3,
        "actions": torch.rand(B, config.horizon, 8, generator=g),
    }


def test_shapes(config):
    B = 3
    unet = ConditionalUnet1D(8, 20, config.down_dims, config.step_embed, config.kernel_size, config.n_groups)
    out = unet(torch.randn(B, config.horizon, 8), torch.tensor([0, 5, 99]), torch.randn(B, 20))
    assert out.shape == (B, config.horizon, 8)
    policy = DiffusionPolicy(config)
    b = batch(config, B)
    cond = policy.condition(policy.net, b["images"], b["states"], b["goal"])
    assert cond.shape == (B, config.n_obs_steps * (config.image_features + 16 + 3))
    loss, parts = policy(**b, generator=torch.Generator().manual_seed(0))
    assert loss.ndim == 0 and torch.isfinite(loss)
    x0_policy = DiffusionPolicy(replace(config, prediction_type="sample"))
    loss, _ = x0_policy(**b, generator=torch.Generator().manual_seed(0))
    assert loss.ndim == 0 and torch.isfinite(loss)
    paper = DiffusionPolicy(PolicyConfig())  # the cpu preset's sizes
    assert 3e6 < paper.num_parameters() < 8e6


def test_sampled_actions_are_thrusts_with_the_right_shape(config):
    policy = DiffusionPolicy(config).eval()
    b = batch(config, 4)
    a = policy.sample_actions(b["images"], b["states"], b["goal"], torch.Generator().manual_seed(1))
    assert a.shape == (4, config.horizon, 8)
    assert a.min() >= 0 and a.max() <= 1
    again = policy.sample_actions(b["images"], b["states"], b["goal"], torch.Generator().manual_seed(1))
    assert torch.equal(a, again)  # every draw from the given generator


def test_config_errors():
    with pytest.raises(ValueError, match="divisible by 4"):
        PolicyConfig(horizon=18, down_dims=(8, 16, 32), n_groups=4, cnn_channels=(8, 8))
    with pytest.raises(ValueError, match="n_action_steps"):
        PolicyConfig(n_action_steps=16)
    with pytest.raises(ValueError, match="image_size"):
        PolicyConfig(image_size=72)
    with pytest.raises(ValueError, match="prediction_type"):
        PolicyConfig(prediction_type="v_prediction")
    with pytest.raises(ValueError, match="timestep_spacing"):
        PolicyConfig(timestep_spacing="middle")


def test_timestep_spacing_decides_where_ddim_starts(config):
    """ "leading" (the reference's) visits 90 .. 0 with 10 of 100 levels, "trailing" 99 .. 9, starting
    where the unit noise it draws belongs; a policy samples with either, whatever its config says."""
    leading = make_schedulers(PolicyConfig())[1].timesteps.tolist()
    trailing = make_schedulers(PolicyConfig(timestep_spacing="trailing"))[1].timesteps.tolist()
    assert leading == list(range(90, -1, -10)) and trailing == list(range(99, 8, -10))
    policy = DiffusionPolicy(config)
    states = torch.zeros(1, config.n_obs_steps, 16)
    images = torch.zeros(1, config.n_obs_steps, 3, config.image_size, config.image_size, dtype=torch.uint8)
    goal = torch.tensor([[3.0, 0.0, 0.0]])
    before = policy.sample_actions(images, states, goal, torch.Generator().manual_seed(0))
    trailing = PolicySampling(timestep_spacing="trailing")
    assert int(policy.sampler_for(trailing).timesteps[0]) == config.train_timesteps - 1
    after = policy.sample_actions(images, states, goal, torch.Generator().manual_seed(0), sampling=trailing)
    assert not torch.equal(before, after)
    assert policy.config == config  # sampling another way never changes the policy
    torch.testing.assert_close(
        policy.sample_actions(images, states, goal, torch.Generator().manual_seed(0)), before, rtol=0, atol=0
    )
    two = PolicySampling(timestep_spacing="trailing", inference_steps=2)
    assert policy.sampler_for(two).timesteps.tolist() == [99, 49]
    with pytest.raises(ValueError, match="inference_steps=101"):
        policy.sample_actions(images, states, goal, sampling=PolicySampling(inference_steps=101))


def test_ddpm_round_trip():
    """Noise added at step k, then removed with the true noise, gives the sample back."""
    ddpm, _ = make_schedulers(PolicyConfig())
    g = torch.Generator().manual_seed(0)
    x0 = torch.rand(2, 16, 8, generator=g) * 2 - 1
    eps = torch.randn(x0.shape, generator=g)
    for k in (0, 1, 50, 99):
        noisy = ddpm.add_noise(x0, eps, torch.tensor([k, k]))
        if k > 0:
            assert not torch.allclose(noisy, x0, atol=1e-3)
        back = ddpm.step(eps, k, noisy, generator=g).pred_original_sample
        torch.testing.assert_close(back, x0, atol=1e-3, rtol=0)  # float32 error divided by sqrt(abar_99) = 5e-4


@pytest.mark.parametrize("prediction_type", ["epsilon", "sample"])
def test_ddim_sampling_with_the_true_noise_returns_the_sample(prediction_type):
    """DDIM from the noised sample, with an oracle network, ends on the sample."""
    ddpm, ddim = make_schedulers(PolicyConfig(prediction_type=prediction_type))
    g = torch.Generator().manual_seed(1)
    x0 = torch.rand(2, 16, 8, generator=g) * 2 - 1
    eps = torch.randn(x0.shape, generator=g)
    start = int(ddim.timesteps[0])
    noisy = ddpm.add_noise(x0, eps, torch.tensor([start, start]))
    oracle = eps if prediction_type == "epsilon" else x0
    out = denoise(ddim, lambda x, k: oracle, noisy)
    torch.testing.assert_close(out, x0, atol=1e-4, rtol=0)
    assert len(ddim.timesteps) == PolicyConfig().inference_steps


def test_goal_in_body_frame():
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))  # a rotation, body -> world
    p = np.array([0.5, -1.0, 2.0])
    goal = np.array([3.0, 1.0, -2.0])
    state = torch.from_numpy(make_state(p, np.zeros(3), R, np.zeros(3), 1.0))
    got = goal_in_body(state, torch.tensor(goal, dtype=torch.float32))
    np.testing.assert_allclose(got.numpy(), R.T @ (goal - p), atol=1e-5)


def test_action_normalisation_round_trip(config):
    policy = DiffusionPolicy(config)
    policy.set_normalisation(torch.zeros(16), torch.ones(16), [0.0] * 7 + [0.2], [0.9] * 7 + [0.2], 2.0)
    a = torch.rand(5, 16, 8) * 0.9
    x = policy.normalise_actions(a)
    assert x[..., :7].min() >= -1 and x[..., :7].max() <= 1
    torch.testing.assert_close(policy.unnormalise_actions(x), a)  # the flat thruster keeps [0, 1]


def test_ema(config):
    assert ema_decay(1, 0.75, 0.9999) == 0.0
    assert 0.99 < ema_decay(1000, 0.75, 0.9999) < ema_decay(100_000, 0.75, 0.9999) <= 0.9999
    policy = DiffusionPolicy(config)
    assert not any(p.requires_grad for p in policy.ema.parameters())
    with torch.no_grad():
        for p in policy.net.parameters():
            p.add_(1.0)
    policy.ema_update(1, 0.75, 0.9999)  # decay 0: a copy
    for e, p in zip(policy.ema.parameters(), policy.net.parameters()):
        assert torch.equal(e, p)
    before = [e.clone() for e in policy.ema.parameters()]
    with torch.no_grad():
        for p in policy.net.parameters():
            p.add_(1.0)
    policy.ema_update(100, 0.75, 0.9999)
    d = ema_decay(100, 0.75, 0.9999)
    for b, e, p in zip(before, policy.ema.parameters(), policy.net.parameters()):
        torch.testing.assert_close(e, d * b + (1 - d) * p)


def test_training_lowers_the_loss(config):
    """90 AdamW steps on a fixed batch lower the loss measured with fixed noise levels and noise."""
    torch.manual_seed(0)
    config = replace(config, down_dims=(32, 64), step_embed=16, n_groups=8)
    policy = DiffusionPolicy(config)
    b = batch(config, 8, seed=3)
    b["actions"] = torch.linspace(0, 1, config.horizon)[None, :, None].expand(8, -1, 8).clone()  # a learnable ramp

    def fixed_loss() -> float:
        with torch.no_grad():
            return float(policy(**b, generator=torch.Generator().manual_seed(123))[0])

    before = fixed_loss()
    optimizer = torch.optim.AdamW(policy.net.parameters(), lr=3e-3)
    for step in range(90):
        loss, _ = policy(**b, generator=torch.Generator().manual_seed(step))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    assert fixed_loss() < 0.85 * before
