"""How a trained Diffusion Policy is sampled and flown, and the named flight presets.

A policy run records how it trained (``PolicyConfig``); how it is sampled is chosen when it is
flown or scored, so one run samples any way without being changed. :class:`PolicySampling`
holds every such setting. It is handed to :meth:`DiffusionPolicy.sample_actions`, to
:class:`DiffusionPilot` and to ``evaluate_policy``, and is never written into the policy.

The presets name what was flown (``--preset NAME`` on ``eval closed-loop``, ``eval policy`` and
``eval expert-floor``; ``--pilot-option preset=NAME`` on ``orbitdata fly``):

- ``cpu``: the reported flight: 8 executed actions of each chunk, one draw, DDIM 10 steps with
  ``trailing`` spacing (chosen on validation seeds, ``docs/results.md``), the camera through the
  dataset's JPEG codec as in training.
- ``reference``: the reference's sampler (``diffusers``' default ``leading`` spacing), otherwise as ``cpu``.

``--set KEY=VALUE`` changes single fields of a preset (:func:`policy_sampling`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

TIMESTEP_SPACINGS = ("leading", "trailing")  # which training noise levels DDIM visits
PICKS = ("mean", "central")  # how a chunk is made of several draws


@dataclass(frozen=True)
class PolicySampling:
    """How a policy samples and executes its chunks (None: the run's own ``PolicyConfig`` value).

    Args:
        action_steps: actions executed from each sampled chunk (the run's ``n_action_steps``).
        ensemble: temporal ensembling (as ACT): every chunk that covers the current frame votes,
            each newer one exp(-ensemble) times the one before (None: no ensembling).
        draws: samples drawn together for each chunk (1: one draw).
        pick: with several draws, fly their ``mean`` or the ``central`` draw (the one nearest
            their mean over the executed actions: a real sample).
        noise_scale: scale of the noise each draw starts from (1: as trained; 0: the one chunk
            that the zero noise gives).
        timestep_spacing: DDIM timestep spacing: ``leading`` (visits 90, 80, .., 0 of 100 levels
            at 10 steps) or ``trailing`` (99, 89, .., 9: unit noise enters at the top level).
        inference_steps: DDIM denoising steps.
        image_codec: hand the policy its camera through the dataset's JPEG codec, as it trained on
            it (closed loop only: the dataset's windows are already encoded; a policy without the
            camera has nothing to encode, and flies with it off).
    """

    action_steps: int | None = None
    ensemble: float | None = None
    draws: int = 1
    pick: str = "mean"
    noise_scale: float = 1.0
    timestep_spacing: str | None = None
    inference_steps: int | None = None
    image_codec: bool = False

    def __post_init__(self):
        if self.action_steps is not None and self.action_steps < 1:
            raise ValueError(f"action_steps={self.action_steps}: execute 1 or more actions of each chunk")
        if self.ensemble is not None and not self.ensemble >= 0:
            raise ValueError(f"ensemble={self.ensemble}: give a decay >= 0 (0: every covering chunk votes alike)")
        if not self.draws >= 1:
            raise ValueError(f"draws={self.draws}: draw 1 or more samples for each chunk")
        if self.pick not in PICKS:
            raise ValueError(f"pick={self.pick!r}: choose one of {', '.join(PICKS)} (how a chunk is made of the draws)")
        if self.pick == "central" and self.draws < 2:
            raise ValueError("pick='central' chooses among several draws: give draws=N with N >= 2")
        if not 0 <= self.noise_scale < float("inf"):
            raise ValueError(f"noise_scale={self.noise_scale}: give a finite scale >= 0 (1: sample as trained)")
        if self.timestep_spacing is not None and self.timestep_spacing not in TIMESTEP_SPACINGS:
            raise ValueError(
                f"timestep_spacing={self.timestep_spacing!r}: choose one of {', '.join(TIMESTEP_SPACINGS)}"
            )
        if self.inference_steps is not None and self.inference_steps < 1:
            raise ValueError(f"inference_steps={self.inference_steps}: give 1 or more DDIM steps")

    def resolved(self, config) -> "PolicySampling":
        """These settings with the run's ``config`` (a ``PolicyConfig``) filling what is None,
        checked against it: what the policy then samples with."""
        most = config.horizon - config.n_obs_steps + 1  # actions a sample holds from the current frame on
        out = dataclasses.replace(
            self,
            action_steps=config.n_action_steps if self.action_steps is None else self.action_steps,
            timestep_spacing=self.timestep_spacing or config.timestep_spacing,
            inference_steps=config.inference_steps if self.inference_steps is None else self.inference_steps,
            image_codec=self.image_codec and config.images,
        )
        if out.action_steps > most:
            raise ValueError(f"action_steps={out.action_steps}: execute 1 to {most} actions of each sampled chunk")
        if out.inference_steps > config.train_timesteps:
            raise ValueError(
                f"inference_steps={out.inference_steps} must be in [1, train_timesteps={config.train_timesteps}]"
            )
        return out

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


POLICY_FLIGHTS: dict[str, Callable[[], PolicySampling]] = {
    "cpu": lambda: PolicySampling(action_steps=8, timestep_spacing="trailing", image_codec=True),
    "reference": lambda: PolicySampling(action_steps=8, timestep_spacing="leading", image_codec=True),
}
DEFAULT_FLIGHT = "cpu"


def policy_sampling(preset: str = DEFAULT_FLIGHT, **options) -> PolicySampling:
    """The flight preset ``preset`` with single fields changed; ``options`` are PolicySampling
    field names, values as a command line gives them (strings) or typed."""
    if preset not in POLICY_FLIGHTS:
        raise ValueError(f"unknown policy flight preset {preset!r}; choose one of {', '.join(POLICY_FLIGHTS)}")
    base = POLICY_FLIGHTS[preset]()
    fields = {f.name: f for f in dataclasses.fields(PolicySampling)}
    changes = {}
    for key, value in options.items():
        if key not in fields:
            raise ValueError(f"unknown policy setting {key!r}; use a field of PolicySampling: {', '.join(fields)}")
        changes[key] = _parse(key, value, getattr(PolicySampling(), key), fields[key].type)
    return dataclasses.replace(base, **changes)


def _parse(key: str, value, default, annotation: str):
    """``value`` (a string from the command line, or already typed) as the field's type."""
    if not isinstance(value, str):
        return value
    if value.lower() == "none" and "None" in annotation:
        return None
    kind = bool if "bool" in annotation else int if "int" in annotation else float if "float" in annotation else str
    if kind is bool:
        if value.lower() not in ("1", "true", "yes", "0", "false", "no"):
            raise ValueError(f"policy setting {key}={value}: give true or false")
        return value.lower() in ("1", "true", "yes")
    try:
        return kind(value)
    except ValueError:
        wanted = {int: "a whole number", float: "a number"}.get(kind, "a string")
        raise ValueError(f"policy setting {key}={value}: give {wanted}") from None
