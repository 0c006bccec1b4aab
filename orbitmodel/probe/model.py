"""The physics probe: reads physical states out of a frozen world model's imagined latents.

    inc_k  = scale * MLP([z_k, z_k - z_{k-1}])    (B, n, 10) increments, per step (z_0: last context latent)
    x_k    = integrate(x_0, inc_1..k)              (B, n, 16) states, steps t+1..t+n

(``config.inputs``: "latent+change" as above, or upstream's "latent", MLP(z_k) alone;
``config.integrator``: upstream's p += dp, v += dv, or "coasting", where zero increments hold
the world-frame velocity; see ``probe.integrator``; ``config.substeps`` u > 1: the MLP gives u
increments per latent, (B, n u, 10), integrated over dt each, so a world model stepping s = u
frames gets a state for every frame, the per-frame head; ``config.inputs`` "thrust": no latent,
each step's thrusts alone, the thrust-only reference of Table I.)

x_0 is the true state at the last context frame. An increment is a change between frames, and a
latent alone says where the craft is, not what just changed (``docs/model.md`` measures what
reading the change does). The MLP sees each step's features independently, so all n increments
come from one batched call and only the attitude product loops over time.

``scale`` is fixed at training start to the RMS of the true per-step increments (metres per step
for dp, fuel ratio per step for dfuel, ...), so the MLP's outputs are of order 1 for every
quantity: dfuel is ~1e-4 per step while dp is ~1e-2, and with raw outputs AdamW's per-weight
steps would swamp the small ones. (Upstream predicts raw increments.)
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from torch import nn

from orbitmodel.kinematics import interpolate_frames
from orbitmodel.model.world_model import mlp
from orbitmodel.probe.config import ProbeConfig
from orbitmodel.probe.integrator import INCREMENT_DIM, integrate
from orbitmodel.probe.variants import FLOWN, folder_name, train_command
from orbitmodel.runs import CONFIG, RunError, load_weights, resolve_run

PROBE_FOLDER = {"latent": "probe", "state": "probe-state"}  # sub-folders of a Stage I run (variants: probe-NAME)


class Increments(nn.Module):
    """MLP features (..., d_in) -> increments (..., 10), in physical units; a probe reading thrusts
    adds a second MLP's increments from the step's (standardised) thrusts. Each frame's rate change
    is linear in its thrusts; concatenated to the latent features they are learnt slowly, so they
    get a branch of their own (docs/model.md). With inputs "...+film" the latent features scale and
    shift that branch's first hidden layer (zero at the start: the additive branch), so what a
    thrust does can depend on the body the latents describe. A probe reading thrusts alone (inputs
    "thrust") has the thrust branch only: no weight sees a latent."""

    def __init__(self, config: ProbeConfig):
        super().__init__()
        self.config = config
        self.net = mlp(config.dims) if config.reads_latent else None
        self.thrust_net = mlp(config.thrust_dims) if config.reads_thrust else None
        # FiLM: the latent features -> a scale and a shift of the thrust branch's first hidden layer
        self.film = nn.Linear(config.dims[0], 2 * config.thrust_dims[1]) if config.modulates_thrust else None
        self.register_buffer("scale", torch.ones(INCREMENT_DIM))
        self.initialize_weights()

    def initialize_weights(self) -> None:
        """Default init for the hidden layers; zero on the output layer, so an untrained probe
        predicts zero increments (upstream integrator: p, v, w and fuel held, the attitude turning
        at w; coasting integrator: constant velocity) and training starts from a smooth loss."""
        for net in (self.net, self.thrust_net):
            if net is not None:
                nn.init.zeros_(net[-1].weight)
                nn.init.zeros_(net[-1].bias)
        if self.film is not None:  # unmodulated at the start: the additive probe
            nn.init.zeros_(self.film.weight)
            nn.init.zeros_(self.film.bias)

    def set_scale(self, scale: torch.Tensor) -> None:
        """Per-increment units (10,): the RMS of the true increments of the training windows."""
        self.scale.copy_(scale.clamp(min=1e-8))

    def forward(self, x: torch.Tensor, thrust: torch.Tensor | None = None) -> torch.Tensor:
        """(B, n, d_in) [and thrusts (B, n, action_dim)] -> (B, n substeps, 10): each step's
        increments in time order."""
        out = self.net(x) if self.net is not None else self.thrust_net(thrust)
        if self.film is not None:
            scale, shift = self.film(x).chunk(2, dim=-1)
            hidden = self.thrust_net[0](thrust) * (1 + scale) + shift
            out = out + self.thrust_net[1:](hidden)
        elif self.net is not None and self.thrust_net is not None:
            out = out + self.thrust_net(thrust)
        return out.reshape(*out.shape[:-2], out.shape[-2] * self.config.substeps, -1) * self.scale


class PhysicsProbe(nn.Module):
    """Latents -> physical states. ``probe(z_future, state0)``; load with :meth:`from_pretrained`."""

    def __init__(self, config: ProbeConfig):
        super().__init__()
        if config.kind != "latent":
            raise ValueError(f"PhysicsProbe reads latents; got a {config.kind!r} probe config")
        self.config = config
        self.increments = Increments(config)
        if config.reads_thrust:  # thrusts in [0, 1] are ~0.1: standardised so the MLP sees them at the latents' scale
            self.register_buffer("thrust_mean", torch.zeros(config.action_dim))
            self.register_buffer("thrust_std", torch.ones(config.action_dim))

    def set_thrust_stats(self, mean, std) -> None:
        """Per-thruster mean and std (8,) of the training data (``meta/stats.json``), tiled over the
        step's frames: a probe reading thrusts standardises them with these."""
        reps = self.config.action_dim // len(mean)
        self.thrust_mean.copy_(torch.as_tensor(mean, dtype=torch.float32).repeat(reps))
        # a thruster the data never fires has std 0: its thrusts then pass through unscaled
        std = torch.as_tensor(std, dtype=torch.float32)
        self.thrust_std.copy_(torch.where(std > 1e-6, std, torch.ones_like(std)).repeat(reps))

    def forward(
        self,
        z_future: torch.Tensor,
        state0: torch.Tensor,
        z_last: torch.Tensor | None = None,
        actions: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """z_future (B, n, D) imagined latents of frames t+1..t+n, state0 (B, 16) the state at
        frame t -> states (B, n substeps, 16) after each integration step (float32). A probe
        that reads latent changes (``config.inputs`` "latent+change...") also needs z_last (B, D),
        the latent of frame t (the last context latent); one that reads thrusts needs actions
        (B, n, action_dim), the action that led to each imagined latent. One that reads thrusts
        alone (inputs "thrust") takes z_future for its shape only."""
        inc = self.step_increments(z_future, z_last, actions)
        return integrate(state0, inc, self.config.dt, self.config.coasting)

    def step_increments(
        self, z_future: torch.Tensor, z_last: torch.Tensor | None = None, actions: torch.Tensor | None = None
    ) -> torch.Tensor:
        """The increments (B, n substeps, 10), in physical units, that :meth:`forward` integrates."""
        D = self.config.latent_dim
        if z_future.shape[-1] != D or z_future.ndim != 3:
            raise ValueError(f"z_future has shape {tuple(z_future.shape)}; expected (B, n, {D})")
        x = z_future
        if self.config.reads_change:
            if z_last is None or z_last.shape != (len(z_future), D):
                got = None if z_last is None else tuple(z_last.shape)
                raise ValueError(
                    f"this probe reads latent changes: pass z_last ({len(z_future)}, {D}), the last "
                    f"context latent (got {got})"
                )
            previous = torch.cat([z_last[:, None].to(z_future), z_future[:, :-1]], dim=1)  # (B, n, D)
            x = torch.cat([z_future, z_future - previous], dim=-1)  # (B, n, 2D)
        if self.config.reads_thrust:
            want = (*z_future.shape[:2], self.config.action_dim)
            if actions is None or tuple(actions.shape) != want:
                got = None if actions is None else tuple(actions.shape)
                raise ValueError(
                    f"this probe reads each step's thrusts: pass actions {want}, the action that led to "
                    f"each imagined latent (got {got})"
                )
            return self.increments(x, (actions.to(x) - self.thrust_mean) / self.thrust_std)
        return self.increments(x)

    def per_frame(
        self,
        z_future: torch.Tensor,
        state0: torch.Tensor,
        z_last: torch.Tensor | None,
        frame_step: int,
        actions: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Every frame's state (B, n frame_step, 16) from the latents of a world model stepping
        ``frame_step`` frames: the probe's own states when it predicts each frame (substeps ==
        frame_step), else its states at the latents interpolated linearly between them
        (:func:`~orbitmodel.kinematics.interpolate_frames`). How the planner and ``eval probe`` read it."""
        states = self(z_future, state0, z_last, actions)
        u = self.config.substeps
        if u == frame_step:
            return states
        if u != 1:
            raise ValueError(f"this probe predicts {u} frames per latent; the world model steps {frame_step}")
        return interpolate_frames(state0.float(), states, frame_step)

    @classmethod
    def from_pretrained(
        cls,
        run_dir: str | Path,
        device: str | torch.device = "cpu",
        world_model: str | None = None,
        revision: str | None = None,
        variant: str = FLOWN,
    ) -> "PhysicsProbe":
        """The probe trained by ``orbitmodel probe RUN``, from ``RUN/probe/`` of a run folder or a Hub
        model repo id (``orbitmodel push``), in eval mode; ``world_model``: the fingerprint of the
        world model it must have been trained on; ``variant``: another of the run's probes
        (``probe.variants``, ``RUN/probe-NAME``)."""
        return from_run(cls, run_dir, "latent", device, world_model, revision, variant)


def probe_folder(run_dir: str | Path, kind: str, variant: str = FLOWN) -> Path:
    """The folder of a run's probe of ``kind``; for the latent kind, of its ``variant``."""
    return Path(run_dir) / (folder_name(variant) if kind == "latent" else PROBE_FOLDER[kind])


def load_probe(
    run_dir: str | Path, kind: str, world_model: str | None = None, variant: str = FLOWN
) -> tuple[ProbeConfig, dict[str, torch.Tensor]]:
    """(config, weights) of a Stage I run's probe of ``kind`` (and ``variant``); RunError with the
    fix if it is absent, or if ``world_model`` (a weights fingerprint) is not the one it was
    trained on."""
    folder = probe_folder(run_dir, kind, variant)
    command = train_command(run_dir, variant) + (" --state-only" if kind == "state" else "")
    if not (folder / CONFIG).is_file():
        what = "state-only reference" if kind == "state" else "physics probe" if variant == FLOWN else variant
        raise RunError(f"{run_dir} has no {what} ({folder} is missing); train it with `{command}`")
    raw = json.loads((folder / CONFIG).read_text())
    try:
        config = ProbeConfig(**raw["probe"])
    except (KeyError, TypeError) as err:
        raise RunError(
            f"{folder / CONFIG} is not a probe config ({err}); train it again with `{command} --overwrite`"
        ) from None
    if world_model is not None and not isinstance(world_model, str):
        raise ValueError(
            f"world_model is a {type(world_model).__name__}: give the world model's fingerprint (model.fingerprint)"
        )
    if world_model is not None and kind == "latent" and raw.get("world_model") != world_model:
        raise RunError(
            f"{folder} was trained on another world model ({raw.get('world_model')}) than the {world_model} "
            f"given: if {run_dir} was trained again, train the probe again with `{command} --overwrite`; "
            "else give its own model's fingerprint"
        )
    try:
        weights = load_weights(folder)
    except RunError:
        raise RunError(f"{folder} has no weights yet; train it with `{command}`") from None
    return config, weights


def from_run(
    cls,
    run_dir: str | Path,
    kind: str,
    device: str | torch.device = "cpu",
    world_model: str | None = None,
    revision: str | None = None,
    variant: str = FLOWN,
):
    """A probe module of class ``cls`` (built from a ProbeConfig) with the weights of ``run_dir``'s
    ``kind`` probe (its ``variant``), in eval mode (see :func:`load_probe`); ``run_dir`` may be a
    Hub repo id."""
    config, weights = load_probe(resolve_run(run_dir, revision), kind, world_model, variant)
    module = cls(config)
    module.load_state_dict(weights)
    return module.to(device).eval()
