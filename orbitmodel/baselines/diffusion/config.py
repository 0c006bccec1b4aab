"""Typed configs of the Diffusion Policy baseline and its named presets.

The reference is Chi et al., *Diffusion Policy* (RSS 2023), code ``real-stanford/diffusion_policy``
(names in brackets below are its config keys). Its published sizes need a GPU for days
(``down_dims [512, 1024, 2048]`` and a ResNet18 per camera, ~280M parameters); ``cpu`` keeps
the design (2 observations, 16 predicted actions, 8 executed, FiLM U-Net, DDPM 100 training
steps, DDIM 10 inference steps, EMA) at ``down_dims (64, 128, 256)`` with a 4-layer CNN on the
64 px image, so that it trains on a 2-core machine within an hour; ``tiny`` is for tests.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

from orbitdata.schema import ACTION_DIM, STATE_DIM
from orbitmodel.baselines.diffusion.sampling import TIMESTEP_SPACINGS
from orbitmodel.data import DatasetMeta
from orbitmodel.loop_settings import LoopSettings, StageTrainConfig
from orbitmodel.runs import CONFIG, POLICY, HeldOut, RunDir, RunError

GOAL_DIM = 3  # the goal in the body frame, metres
FAMILY = "diffusion"  # config.json's "policy": the policy family of a policy run
PREDICTION_TYPES = ("epsilon", "sample")


@dataclass(frozen=True)
class PolicyConfig:
    """Sizes and diffusion settings of the policy.

    Args:
        image_size: square RGB input in pixels (the dataset's; no resizing).
        n_obs_steps: observations the policy is conditioned on (frames t-1, t) [n_obs_steps].
        horizon: actions predicted per sample, for frames t-1 .. t+14 [horizon].
        n_action_steps: actions executed from a sample, for frames t .. t+7 [n_action_steps].
        cnn_channels: widths of the image encoder's stride-2 3x3 convolutions.
        image_features: the image encoder's output width per observation.
        n_groups: GroupNorm groups in the CNN and the U-Net [n_groups] (GroupNorm, not
            BatchNorm: the reference notes that EMA destroys performance with BatchNorm).
        down_dims: channel widths of the U-Net's levels [down_dims].
        step_embed: width of the diffusion-step embedding [diffusion_step_embed_dim].
        kernel_size: temporal kernel of the U-Net's convolutions [kernel_size].
        train_timesteps: DDPM noise levels in training [num_train_timesteps].
        inference_steps: DDIM denoising steps when acting [num_inference_steps], unless the
            flight's ``PolicySampling`` gives its own.
        timestep_spacing: which of the training noise levels DDIM visits (``diffusers``' option):
            "leading" (the reference's, its default: 10 of 100 steps visit 90, 80, .., 0, so the
            unit starting noise enters at level 90) or "trailing" (99, 89, .., 9: it enters at
            the top level, where unit noise belongs). Sampling only, and the run's default: a
            flight preset (``sampling.POLICY_FLIGHTS``) names its own, so any run samples either way.
        beta_schedule: the noise schedule's name in ``diffusers`` [beta_schedule].
        clip_sample: clip the predicted clean sample to [-1, 1] at each step [clip_sample].
        prediction_type: what the U-Net predicts [prediction_type]: "epsilon" (the noise, the
            reference's default) or "sample" (the clean action sequence, its other option).
        images: condition on the camera (False: on the states and the goal only, a variant that
            cannot see obstacles; no image is decoded, rendered or encoded for it).
        obstacles: privileged, a diagnostic: also condition on the episode's true obstacles, up to
            this many (each one's centre relative to the craft in the body frame and its bounding
            radius; 0: none). It measures how much of the action error the camera leaves; such a
            policy cannot fly (no pilot is told the obstacles).
    """

    image_size: int = 64
    n_obs_steps: int = 2
    horizon: int = 16
    n_action_steps: int = 8
    cnn_channels: tuple[int, ...] = (32, 64, 128, 256)
    image_features: int = 64
    n_groups: int = 8
    down_dims: tuple[int, ...] = (64, 128, 256)
    step_embed: int = 64
    kernel_size: int = 5
    train_timesteps: int = 100
    inference_steps: int = 10
    timestep_spacing: str = "leading"
    beta_schedule: str = "squaredcos_cap_v2"
    clip_sample: bool = True
    prediction_type: str = "epsilon"
    state_dim: int = STATE_DIM
    action_dim: int = ACTION_DIM
    images: bool = True
    obstacles: int = 0

    def __post_init__(self):
        if self.obstacles < 0:
            raise ValueError(f"obstacles={self.obstacles}: give the number of true obstacles to read, 0 for none")
        levels = 2 ** (len(self.down_dims) - 1)
        if self.horizon % levels:
            raise ValueError(
                f"horizon={self.horizon} must be divisible by {levels}: the U-Net halves it "
                f"{len(self.down_dims) - 1} times (down_dims={self.down_dims})"
            )
        if self.n_obs_steps < 1:
            raise ValueError(f"n_obs_steps={self.n_obs_steps}: condition on at least one observation")
        if not 1 <= self.n_action_steps <= self.horizon - self.n_obs_steps + 1:
            raise ValueError(
                f"n_action_steps={self.n_action_steps} must be in [1, horizon - n_obs_steps + 1 = "
                f"{self.horizon - self.n_obs_steps + 1}]: executed actions start at the current frame"
            )
        if not 1 <= self.inference_steps <= self.train_timesteps:
            raise ValueError(
                f"inference_steps={self.inference_steps} must be in [1, train_timesteps={self.train_timesteps}]"
            )
        if self.timestep_spacing not in TIMESTEP_SPACINGS:
            raise ValueError(
                f"timestep_spacing={self.timestep_spacing!r}: choose one of {', '.join(TIMESTEP_SPACINGS)}"
            )
        if self.prediction_type not in PREDICTION_TYPES:
            raise ValueError(f"prediction_type={self.prediction_type!r}: choose one of {', '.join(PREDICTION_TYPES)}")
        side = 2 ** len(self.cnn_channels)
        if self.image_size % side:
            raise ValueError(
                f"image_size={self.image_size} must be divisible by {side} "
                f"({len(self.cnn_channels)} stride-2 convolutions)"
            )
        for name in ("cnn_channels", "down_dims"):
            bad = [c for c in getattr(self, name) if c % self.n_groups]
            if bad:
                raise ValueError(f"{name}={getattr(self, name)}: {bad} not divisible by n_groups={self.n_groups}")
        object.__setattr__(self, "cnn_channels", tuple(self.cnn_channels))
        object.__setattr__(self, "down_dims", tuple(self.down_dims))

    @property
    def action_start(self) -> int:
        """Index in a sample of the first executed action: the current frame t."""
        return self.n_obs_steps - 1


@dataclass(frozen=True)
class PolicyTrainConfig(StageTrainConfig):
    """How the policy trains (reference: AdamW 1e-4, betas (0.95, 0.999), wd 1e-6, cosine
    with 500 warm-up steps, batch 64 for images, EMA power 0.75 up to 0.9999).

    Args:
        window_stride: frames between the starts of two training windows of an episode.
        ema_power, ema_max: EMA decay after k optimiser steps is min(ema_max, 1 - k^-power).
        shift: random-shift augmentation, pixels (pad by replication, crop back); 0 = none.
            The reference crops randomly (84 -> 76); at 64 px a +-4 px shift plays that role.
        val_fraction, val_seed: hold this seeded fraction of the train split's episodes (per
            level) out of training, for choices (``eval policy --split val``; 0: none).
        pad_before: per episode, this many extra windows that start before its first frame
            (the first observation repeated in front, as the pilot does at its first step; the
            reference's ``n_obs_steps - 1``; 0: none).
        mask_padding: the terminal frame and the padding past an episode's end add no loss
            (False: they are targets like any frame, as in runs made before this option).
        loop: the training loop's settings (``loop_settings.LoopSettings``); its seed also draws
            the noise and the augmentation.
    """

    window_stride: int = 1
    ema_power: float = 0.75
    ema_max: float = 0.9999
    shift: int = 4
    val_fraction: float = 0.0
    val_seed: int = 0
    pad_before: int = 1
    mask_padding: bool = True
    loop: LoopSettings = LoopSettings(
        batch_size=64,
        lr=1e-4,
        min_lr=0.0,
        weight_decay=1e-6,
        betas=(0.95, 0.999),
        epochs=100,
        max_steps=0,
        warmup=0.05,
        grad_clip=10.0,
        num_workers=4,
        log_every=10,
        save_every=500,
        seed=42,
    )

    def __post_init__(self):
        if not 0.0 <= self.val_fraction < 1.0:
            raise ValueError(f"val_fraction={self.val_fraction} must be in [0, 1)")
        if self.pad_before < 0:
            raise ValueError(f"pad_before={self.pad_before}: give 0 or more frames")
        if self.window_stride < 1:
            raise ValueError(f"window_stride={self.window_stride}: use 1 or more frames")
        if not 0 <= self.ema_max < 1 or self.ema_power <= 0:
            raise ValueError(f"ema_max={self.ema_max}, ema_power={self.ema_power}: need 0 <= ema_max < 1, power > 0")
        if self.shift < 0:
            raise ValueError(f"shift={self.shift}: give a non-negative number of pixels")


@dataclass(frozen=True)
class PolicyPreset:
    """A policy size and the training recipe that goes with it."""

    name: str
    description: str
    model: PolicyConfig
    train: PolicyTrainConfig = field(default_factory=PolicyTrainConfig)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "PolicyPreset":
        """A preset as a run's config.json holds it (its training config nested or flat, see
        ``StageTrainConfig.from_dict``)."""
        model = {k: tuple(v) if isinstance(v, list) else v for k, v in d["model"].items()}
        return cls(
            name=d["name"],
            description=d["description"],
            model=PolicyConfig(**model),
            train=PolicyTrainConfig.from_dict(d["train"]),
        )

    def with_train(self, **changes) -> "PolicyPreset":
        """The preset with some training settings replaced, the loop's by their own names
        (``StageTrainConfig.with_changes``; None values are ignored)."""
        return replace(self, train=self.train.with_changes(**changes))


def _cpu() -> PolicyPreset:
    # 16,000 steps (about 5 epochs of the expert windows; the steps-vs-MSE curve in
    # docs/results.md). The reference's epsilon prediction samples badly at small budgets (DDIM
    # samples far from the data, biased by the clipped x0 estimates of the noisiest steps), so the
    # preset predicts the clean sample (the reference's other prediction_type) at a 3x higher
    # learning rate.
    train = PolicyTrainConfig().with_changes(
        batch_size=64, lr=3e-4, epochs=100, max_steps=16000, warmup=0.05, num_workers=0, log_every=20, save_every=250
    )
    return PolicyPreset(
        "cpu",
        "Diffusion Policy for a 2-core CPU: 4-layer GroupNorm CNN on 64 px, U-Net "
        "(64, 128, 256), DDPM 100 / DDIM 10, x0 prediction",
        PolicyConfig(prediction_type="sample"),
        train,
    )


def _cpu_state() -> PolicyPreset:
    # The cpu policy and recipe without the camera: a second baseline row, and a cheap proxy of
    # how much of the policy's skill needs no vision.
    cpu = _cpu()
    return PolicyPreset(
        "cpu-state",
        "the cpu Diffusion Policy on states and goal only (no camera)",
        replace(cpu.model, images=False),
        cpu.train,
    )


def _cpu_state_obstacles() -> PolicyPreset:
    # The diagnostic beside cpu-state: the same policy told the episode's true obstacles (up to 5,
    # the dataset's most), so its error is what perfect perception would leave. It does not fly.
    blind = _cpu_state()
    return PolicyPreset(
        "cpu-state-obstacles",
        "diagnostic: cpu-state told the true obstacles (privileged; does not fly)",
        replace(blind.model, obstacles=5),
        blind.train,
    )


def _tiny() -> PolicyPreset:
    model = PolicyConfig(
        cnn_channels=(8, 8, 8, 8),
        image_features=8,
        n_groups=4,
        down_dims=(8, 16),
        step_embed=8,
        kernel_size=3,
        inference_steps=4,
    )
    train = PolicyTrainConfig().with_changes(
        window_stride=4,
        batch_size=4,
        lr=1e-3,
        epochs=2,
        warmup=0.1,
        shift=2,
        num_workers=0,
        log_every=1,
        save_every=2,
        seed=0,
    )
    return PolicyPreset("tiny", "a tiny policy for tests", model, train)


POLICY_PRESETS: dict[str, Callable[[], PolicyPreset]] = {
    "cpu": _cpu,
    "cpu-state": _cpu_state,
    "cpu-state-obstacles": _cpu_state_obstacles,
    "tiny": _tiny,
}


def get_policy_preset(name: str) -> PolicyPreset:
    if name not in POLICY_PRESETS:
        raise ValueError(f"unknown policy preset {name!r}; choose one of {', '.join(POLICY_PRESETS)}")
    return POLICY_PRESETS[name]()


@dataclass(frozen=True)
class PolicyRun(HeldOut):
    """A policy run's preset and dataset facts (and the raw config.json)."""

    preset: PolicyPreset
    dataset: DatasetMeta
    raw: dict


def read_policy_run(path: str | Path) -> PolicyRun:
    """A policy run's preset and dataset facts, from its config.json; RunError for anything else."""
    raw = RunDir(path).read_config()
    if raw.get("stage") != POLICY or raw.get("policy") != FAMILY:
        raise RunError(
            f"{path} holds a {raw.get('stage', 'unknown')!r} run, not a diffusion policy; "
            "train one with `orbitmodel train-policy DATASET --out RUN`"
        )
    try:
        return PolicyRun(PolicyPreset.from_dict(raw["preset"]), DatasetMeta.from_dict(raw["dataset"]), raw)
    except (KeyError, TypeError, ValueError) as err:
        raise RunError(f"{Path(path) / CONFIG} is not a policy run config ({err})") from None
