"""Diffusion Policy (Chi et al. 2023): a denoiser of action sequences conditioned on observations.

Training (DDPM)::

    a_0   = minmax(actions)               (B, H, 8) in [-1, 1], frames t-1 .. t+14
    k ~ U{0..K-1}, eps ~ N(0, I)          per window, from the step's seeded generator
    a_k   = sqrt(abar_k) a_0 + sqrt(1 - abar_k) eps        DDPMScheduler.add_noise
    loss  = || eps - UNet(a_k, k, ObsEncoder(o_{t-1}, o_t)) ||^2      (prediction_type "epsilon")
          = || a_0 - UNet(...) ||^2                                    (prediction_type "sample")

Acting: a ~ N(0, I), then ``inference_steps`` DDIM steps (deterministic, eta 0) with the EMA
weights; the actions for frames t .. t+7 are executed. Both schedules come from ``diffusers``
with the reference's settings (100 steps, squaredcos_cap_v2, clip_sample, epsilon or sample).

States and actions are normalised inside the module from the dataset's ``meta/stats.json``
(states by mean/std, actions min-max to [-1, 1], the goal by the position's spread), so
callers pass raw dataset values: images uint8, states (16,), the goal in metres, world frame
relative to the start, and actions in [0, 1].
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Callable

import torch
import torch.nn.functional as F
from torch import nn

from orbitmodel.baselines.diffusion.config import PolicyConfig, read_policy_run
from orbitmodel.baselines.diffusion.encoder import ObservationEncoder
from orbitmodel.baselines.diffusion.sampling import PolicySampling
from orbitmodel.baselines.diffusion.unet import ConditionalUnet1D
from orbitmodel.kinematics import P, body_to_world
from orbitmodel.model.normalise import NormalisedStates
from orbitmodel.runs import RunError, load_weights, resolve_run


def goal_in_body(states: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """R^T (goal - p): states (..., 16), goal (..., 3) metres world frame -> (..., 3) metres body frame."""
    R = body_to_world(states)  # (..., 3, 3)
    return (R.transpose(-1, -2) @ (goal - states[..., P])[..., None]).squeeze(-1)


def make_schedulers(config: PolicyConfig, sampling: PolicySampling | None = None):
    """(DDPMScheduler for training, DDIMScheduler for acting with ``sampling``'s DDIM steps and
    spacing, the run's own where it gives None)."""
    from diffusers import DDIMScheduler, DDPMScheduler

    s = (sampling or PolicySampling()).resolved(config)
    ddpm = DDPMScheduler(
        num_train_timesteps=config.train_timesteps,
        beta_schedule=config.beta_schedule,
        variance_type="fixed_small",
        clip_sample=config.clip_sample,
        prediction_type=config.prediction_type,
    )
    ddim = DDIMScheduler(
        num_train_timesteps=config.train_timesteps,
        beta_schedule=config.beta_schedule,
        clip_sample=config.clip_sample,
        set_alpha_to_one=True,
        steps_offset=0,
        prediction_type=config.prediction_type,
        timestep_spacing=s.timestep_spacing,
    )
    ddim.set_timesteps(s.inference_steps)
    return ddpm, ddim


def denoise(
    scheduler,
    predict: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    sample: torch.Tensor,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Run ``scheduler``'s reverse process from ``sample`` (B, H, A): predict(x, k (B,)) is the
    network's output (the noise or the clean sample, as the scheduler's prediction_type says)."""
    for k in scheduler.timesteps:
        out = predict(sample, k.expand(len(sample)).to(sample.device))
        sample = scheduler.step(out, k, sample, generator=generator).prev_sample
    return sample


def ema_decay(step: int, power: float, max_decay: float) -> float:
    """The reference's EMA warm-up: 0 at the first update, then 1 - step^-power, capped."""
    return 0.0 if step <= 1 else min(max_decay, 1.0 - step**-power)


class Denoiser(nn.Module):
    """The trained network: observation encoder + conditional U-Net."""

    def __init__(self, config: PolicyConfig):
        super().__init__()
        self.obs_encoder = ObservationEncoder(config)
        self.unet = ConditionalUnet1D(
            config.action_dim,
            self.obs_encoder.out_dim,
            config.down_dims,
            config.step_embed,
            config.kernel_size,
            config.n_groups,
        )


class DiffusionPolicy(NormalisedStates, nn.Module):
    """The policy with its EMA copy and normalisation. Build it from a :class:`PolicyConfig`, or
    load a trained one with :meth:`from_pretrained`."""

    def __init__(self, config: PolicyConfig):
        super().__init__()
        self.config = config
        self.net = Denoiser(config)
        self.ema = copy.deepcopy(self.net).requires_grad_(False)  # updated by ema_update after each step
        self.register_state_stats(config.state_dim)
        self.register_buffer("action_low", torch.zeros(config.action_dim))
        self.register_buffer("action_high", torch.ones(config.action_dim))
        self.register_buffer("goal_scale", torch.tensor(1.0))  # metres per unit of the goal input
        self.noise_scheduler, own = make_schedulers(config)
        s = PolicySampling().resolved(config)
        self._samplers: dict[tuple[str, int], object] = {
            (s.timestep_spacing, s.inference_steps): own
        }  # by DDIM setting

    @property
    def sampler(self):
        """The run's own DDIM scheduler (its config's spacing and steps): ``sampler_for(None)``."""
        return self.sampler_for()

    def sampler_for(self, sampling: PolicySampling | None = None):
        """The DDIM scheduler that ``sampling`` asks for (None: the run's own). Training does not
        depend on it, so any run samples either way; the policy itself is never changed."""
        s = (sampling or PolicySampling()).resolved(self.config)
        key = (s.timestep_spacing, s.inference_steps)
        if key not in self._samplers:
            self._samplers[key] = make_schedulers(self.config, s)[1]
        return self._samplers[key]

    def set_normalisation(self, state_mean, state_std, action_low, action_high, goal_scale: float) -> None:
        """Take the dataset's statistics (meta/stats.json): state mean/std (16,), action min/max (8,),
        and the goal's scale in metres. A thruster whose min equals its max keeps [0, 1]."""
        low = torch.as_tensor(action_low, dtype=torch.float32)
        high = torch.as_tensor(action_high, dtype=torch.float32)
        flat = high - low < 1e-6
        self.set_state_stats(state_mean, state_std)
        self.action_low.copy_(torch.where(flat, torch.zeros_like(low), low))
        self.action_high.copy_(torch.where(flat, torch.ones_like(high), high))
        self.goal_scale.fill_(max(float(goal_scale), 1e-3))

    # ---- normalisation ----------------------------------------------------------------------
    def normalise_actions(self, actions: torch.Tensor) -> torch.Tensor:  # (..., 8) [0, 1] -> [-1, 1]
        return (actions - self.action_low) / (self.action_high - self.action_low) * 2 - 1

    def unnormalise_actions(self, x: torch.Tensor) -> torch.Tensor:  # (..., 8) [-1, 1] -> thrust in [0, 1]
        return ((x + 1) / 2 * (self.action_high - self.action_low) + self.action_low).clamp(0.0, 1.0)

    def condition(
        self,
        net: Denoiser,
        images: torch.Tensor,
        states: torch.Tensor,
        goal: torch.Tensor,
        obstacles: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """images (B, To, 3, S, S) uint8 (ignored, may be None, for a policy without images), states
        (B, To, 16), goal (B, 3) metres world frame, and for a privileged policy obstacles (B, K, 4):
        the true obstacles' centres (metres, world frame) and bounding radii (0: an empty slot) -> (B, C)."""
        if self.config.images and images is None:
            raise ValueError("this policy sees the camera: pass its images")
        x = images.float() / 127.5 - 1.0 if self.config.images else None  # [-1, 1]
        s = self.normalise_states(states)
        To = states.shape[1]
        g = goal_in_body(states, goal[:, None, :].expand(-1, To, -1)) / self.goal_scale  # (B, To, 3)
        o = None
        if self.config.obstacles:
            if obstacles is None or obstacles.shape[1:] != (self.config.obstacles, 4):
                raise ValueError(
                    f"this policy is privileged: pass the episode's true obstacles as (B, "
                    f"{self.config.obstacles}, 4) centres and radii"
                )
            K = obstacles.shape[1]
            here = (obstacles[:, None, :, 3:] > 0).to(states.dtype).expand(-1, To, -1, -1)  # (B, To, K, 1)
            centre = goal_in_body(
                states[:, :, None].expand(-1, -1, K, -1), obstacles[:, None, :, :3].expand(-1, To, -1, -1)
            )  # (B, To, K, 3)
            radius = obstacles[:, None, :, 3:].expand(-1, To, -1, -1)
            o = torch.cat([centre * here / self.goal_scale, radius / self.goal_scale, here], -1)  # (B, To, K, 5)
        return net.obs_encoder(x, s, g, o)

    # ---- training ---------------------------------------------------------------------------
    def loss(
        self,
        images: torch.Tensor,
        states: torch.Tensor,
        goal: torch.Tensor,
        actions: torch.Tensor,
        generator: torch.Generator | None = None,
        real: torch.Tensor | None = None,
        obstacles: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """DDPM loss on the noise (or the clean sample). images (B, To, 3, S, S) uint8, states (B, To, 16), goal (B, 3),
        actions (B, H, 8) in [0, 1]; noise levels and noise come from ``generator`` (CPU). ``real``
        (B, H) bool: the frames whose action was really taken; the others (the terminal frame's
        zero thrust, and the padding that repeats it past an episode's end) add no loss."""
        B = len(actions)
        a0 = self.normalise_actions(actions)  # (B, H, 8)
        k = torch.randint(0, self.config.train_timesteps, (B,), generator=generator).to(a0.device)
        eps = torch.randn(a0.shape, generator=generator).to(a0.device)
        noisy = self.noise_scheduler.add_noise(a0, eps, k)
        pred = self.net.unet(noisy, k, self.condition(self.net, images, states, goal, obstacles))
        target = eps if self.config.prediction_type == "epsilon" else a0
        if real is None:
            return F.mse_loss(pred.float(), target), {}
        weight = real.to(pred.device, torch.float32)[..., None]  # (B, H, 1)
        error = ((pred.float() - target) ** 2 * weight).sum() / (weight.sum() * pred.shape[-1]).clamp(min=1.0)
        return error, {"real_frames": weight.mean().detach()}

    def forward(self, images, states, goal, actions, generator=None, real=None, obstacles=None):
        """The training loss (so DDP sees a forward): see :meth:`loss`."""
        return self.loss(images, states, goal, actions, generator, real, obstacles)

    @torch.no_grad()
    def ema_update(self, step: int, power: float, max_decay: float) -> None:
        """ema <- decay * ema + (1 - decay) * net, after optimiser step ``step`` (1-based)."""
        decay = ema_decay(step, power, max_decay)
        for e, p in zip(self.ema.parameters(), self.net.parameters()):
            e.lerp_(p.detach(), 1.0 - decay)
        for e, b in zip(self.ema.buffers(), self.net.buffers()):
            e.copy_(b)

    # ---- acting -----------------------------------------------------------------------------
    @torch.no_grad()
    def sample_actions(
        self,
        images: torch.Tensor,
        states: torch.Tensor,
        goal: torch.Tensor,
        generator: torch.Generator | None = None,
        use_ema: bool = True,
        obstacles: torch.Tensor | None = None,
        sampling: PolicySampling | None = None,
        noise: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """A sampled action sequence (B, H, 8), thrust in [0, 1], for frames t-1 .. t+H-2, from
        observations of frames t-To+1 .. t (see :meth:`condition`). Execute
        ``[:, config.action_start : config.action_start + action_steps]``.

        ``sampling`` (None: the run's own DDIM settings, noise as trained) chooses the DDIM steps
        and spacing, and ``noise_scale``, which scales the initial noise that DDIM's deterministic
        reverse process starts from: 1 samples as trained; below 1 the samples gather towards the
        chunk that the zero noise gives (0: that one chunk for every draw). The generator
        advances alike whatever the scale. ``noise`` (B, H, 8): that initial noise, drawn and
        scaled by the caller (the lockstep flights draw each episode's rows from its own
        generator); DDIM's reverse process draws nothing more."""
        sampling = sampling or PolicySampling()
        sampler = self.sampler_for(sampling)
        net = self.ema if use_ema else self.net
        device = self.state_mean.device
        images = images.to(device) if images is not None else None
        obstacles = obstacles.to(device).float() if obstacles is not None else None
        cond = self.condition(net, images, states.to(device).float(), goal.to(device).float(), obstacles)
        c = self.config
        if noise is None:
            noise = sampling.noise_scale * torch.randn((len(cond), c.horizon, c.action_dim), generator=generator)
        elif noise.shape != (len(cond), c.horizon, c.action_dim):
            raise ValueError(f"noise of shape {tuple(noise.shape)}; expected {(len(cond), c.horizon, c.action_dim)}")
        x = noise.to(device)
        x = denoise(sampler, lambda xk, k: net.unet(xk, k, cond), x, generator)
        return self.unnormalise_actions(x)

    # ---- persistence ------------------------------------------------------------------------
    def num_parameters(self) -> int:
        """Trained parameters (the EMA copy not counted)."""
        return sum(p.numel() for p in self.net.parameters())

    @classmethod
    def from_pretrained(
        cls, path: str | Path, device: str | torch.device = "cpu", revision: str | None = None
    ) -> "DiffusionPolicy":
        """Load a trained policy, in eval mode, from a run folder (``orbitmodel train-policy --out
        RUN``) or a Hub model repo id (``orbitmodel push``; ``revision`` or ``owner/name@rev``)."""
        path = resolve_run(path, revision)
        run = read_policy_run(path)
        policy = cls(run.preset.model)
        try:
            policy.load_state_dict(load_weights(path))
        except RuntimeError as err:
            raise RunError(
                f"{path}: the weights do not fit the config's policy ({str(err).splitlines()[0]}); train the run again"
            ) from None
        policy.run_info = run.dataset
        return policy.to(device).eval()
