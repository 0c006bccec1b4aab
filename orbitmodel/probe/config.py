"""Typed configs of Stage II: the probe's size and how it trains, with one recipe per Stage I preset.

Upstream (configs/stage2.yaml): MLP 256 -> 256 -> GELU -> 256 -> GELU -> 10, windows of 8 + 12
frames, loss weights pos 1, vel 1, rot6d 1, w 1, fuel 0.1, AdamW 3e-4, wd 0.01, batch 256,
25 epochs with 3 of warm-up, cosine, clip 1.0, bf16. The ``cpu`` recipe keeps the model, trains
on a cache of imagined latents to fit a few minutes of a 2-core machine, and weights fuel so that
it trains at all (measured; see the README). Which latents the MLP reads (``inputs``) and how the
increments integrate (``integrator``) are ProbeConfig fields, chosen per preset by
``default_probe``: upstream's (latent, upstream) for ``paper``, the measured best
(latent+change, coasting) for the others.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from orbitdata import schema as S
from orbitmodel.config import replace_given

KINDS = ("latent", "state")  # the probe on imagined latents; the state-only reference MLP
INTEGRATORS = ("upstream", "coasting")
INPUTS = ("latent", "latent+change")  # what the latent probe's MLP reads per step


@dataclass(frozen=True)
class ProbeConfig:
    """The probe MLP (and the state-only reference, which has the same body).

    Args:
        kind: "latent": reads a world model's imagined latents; "state": reads (state, action).
        latent_dim: the world model's z size (latent kind) or 16 + 8 (state kind).
        hidden, layers: ``layers`` hidden layers of ``hidden`` units with GELU, then 10 outputs.
        dt: seconds per step; the attitude integrates exp(w' dt).
        inputs: "latent" (upstream): the MLP reads z_k. "latent+change": it reads [z_k, z_k - z_{k-1}]
            (z_0 the last context latent): the world model predicts the change of z, and the
            increments are about change.
        integrator: "upstream": p' = p + dp, v' = v + dv. "coasting": zero increments hold the
            world-frame velocity and the position follows it; the increments are what thrust
            changes (see ``probe.integrator``).
    """

    kind: str = "latent"
    latent_dim: int = 256
    hidden: int = 256
    layers: int = 2
    dt: float = S.DT
    inputs: str = "latent"
    integrator: str = "upstream"

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"probe kind {self.kind!r}: choose one of {', '.join(KINDS)}")
        if self.inputs not in INPUTS or (self.kind == "state" and self.inputs != "latent"):
            raise ValueError(f"inputs {self.inputs!r}: choose one of {', '.join(INPUTS)} "
                             "(the state kind reads its own)")
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"integrator {self.integrator!r}: choose one of {', '.join(INTEGRATORS)}")
        if self.layers < 1 or self.hidden < 1:
            raise ValueError(f"layers={self.layers}, hidden={self.hidden}: give at least one hidden layer")

    @property
    def coasting(self) -> bool:
        return self.integrator == "coasting"

    @property
    def reads_change(self) -> bool:
        return self.inputs == "latent+change"

    @property
    def dims(self) -> tuple[int, ...]:
        d_in = 2 * self.latent_dim if self.reads_change else self.latent_dim
        return (d_in, *([self.hidden] * self.layers), 10)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class ProbeTrainConfig:
    """How Stage II trains; the loop's fields (see ``LoopSettings``) plus the windows and the loss.

    Args:
        context, horizon, window_stride: windows of ``context + horizon`` frames, ``window_stride``
            apart; the probe integrates from the last context frame over the horizon.
        weights: loss weights of (position, velocity, rot6d, angular velocity, fuel) MSE.
        cache_windows: 0: every step runs the frozen world model on its batch (upstream). N > 0:
            train on a seeded subset of N windows whose imagined latents are computed once and
            kept (see ``probe.cache``); the state-only reference then trains on the same N.
        scale_windows: training windows whose true increments set the output scale.
        batch_size ... seed: as in Stage I's TrainConfig.
    """

    context: int = 8
    horizon: int = 12
    window_stride: int = 1
    weights: tuple[float, float, float, float, float] = (1.0, 1.0, 1.0, 1.0, 0.1)
    cache_windows: int = 0
    scale_windows: int = 2048
    batch_size: int = 256
    lr: float = 3e-4
    min_lr: float = 0.0
    weight_decay: float = 0.01
    betas: tuple[float, float] = (0.9, 0.999)
    epochs: int = 25
    max_steps: int = 0
    warmup: float = 0.12  # 3 of 25 epochs
    grad_clip: float = 1.0
    num_workers: int = 4
    log_every: int = 10
    save_every: int = 500
    seed: int = 42

    def __post_init__(self):
        if self.context < 1 or self.horizon < 1:
            raise ValueError(f"context={self.context}, horizon={self.horizon}: both must be >= 1")
        if len(self.weights) != 5:
            raise ValueError(f"weights={self.weights}: give 5 (position, velocity, rot6d, w, fuel)")
        if self.cache_windows < 0:
            raise ValueError(f"cache_windows={self.cache_windows}: give 0 (no cache) or a number of windows")
        if self.epochs < 1 or self.max_steps < 0 or self.batch_size < 1:
            raise ValueError(f"epochs={self.epochs}, max_steps={self.max_steps}, batch_size={self.batch_size}: "
                             "give epochs >= 1, max_steps >= 0, batch_size >= 1")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ProbeTrainConfig":
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})

    def with_changes(self, **changes) -> "ProbeTrainConfig":
        """The config with some settings replaced (None values are ignored)."""
        return replace_given(self, **changes)


# The probe's training recipe for each Stage I preset (by the run's preset name).
RECIPES: dict[str, ProbeTrainConfig] = {
    "paper": ProbeTrainConfig(),
    # fuel weight 100, not 0.1: fuel moves ~1e-4 per step, so at 0.1 its MSE is ~1e-5 of the
    # loss and gets no gradient to speak of (measured: fuel MAE 0.0025 -> 0.0019 at h = 25).
    # 60 epochs, not 30: velocity at h = 50 0.134 -> 0.117 m/s (3.3 min on 1 thread).
    "cpu": ProbeTrainConfig(window_stride=3, weights=(1.0, 1.0, 1.0, 1.0, 100.0), cache_windows=10240,
                            batch_size=128, lr=1e-3, min_lr=1e-5, epochs=60, warmup=0.05, num_workers=0,
                            log_every=20, save_every=200),
    "tiny": ProbeTrainConfig(context=4, horizon=4, window_stride=2, cache_windows=32, scale_windows=64, batch_size=4,
                             lr=3e-3, epochs=2, warmup=0.1, num_workers=0, log_every=1, save_every=2, seed=0),
}


def default_probe(preset_name: str) -> tuple[str, str]:
    """(inputs, integrator) of the probe for a Stage I preset: upstream's for ``paper``, the
    measured best (latent+change, coasting; README) for every other preset."""
    return ("latent", "upstream") if preset_name == "paper" else ("latent+change", "coasting")


def recipe(preset_name: str) -> ProbeTrainConfig:
    """The recipe for a Stage I preset; upstream's for a preset without one."""
    return RECIPES.get(preset_name, RECIPES["paper"])
