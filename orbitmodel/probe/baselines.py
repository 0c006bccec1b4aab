"""Reference predictors for the probe's table, computed on the same windows:

* :class:`StateDynamics`: an MLP from (state, action) to the same increments, integrated the
  same way and rolled out on its own predictions. It sees the true state at the last context
  frame and the actions, never an image: what the latent model adds is the gap to this row.
* :func:`constant_velocity`: coast from the last context state with no thrust: world-frame
  velocity and body rates held (exact for the torque-free, isotropic CubeSat), fuel held.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from orbitdata import schema as S
from orbitmodel.model.normalise import NormalisedStates
from orbitmodel.probe.config import ProbeConfig
from orbitmodel.probe.integrator import INCREMENT_DIM, integrate, step
from orbitmodel.probe.model import Increments, from_run

STATE_ACTION_DIM = S.STATE_DIM + S.ACTION_DIM


class StateDynamics(NormalisedStates, nn.Module):
    """(state, action) -> increments, rolled out autoregressively: ``model(state0, actions)``."""

    def __init__(self, config: ProbeConfig):
        super().__init__()
        if config.kind != "state" or config.latent_dim != STATE_ACTION_DIM:
            raise ValueError(
                f"StateDynamics takes a 'state' probe config with latent_dim {STATE_ACTION_DIM}, "
                f"got kind {config.kind!r}, latent_dim {config.latent_dim}"
            )
        self.config = config
        self.increments = Increments(config)
        self.register_state_stats(S.STATE_DIM)

    def forward(self, state0: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """state0 (B, 16) at frame t, actions (B, n, 8) in [0, 1] applied at frames t..t+n-1
        -> states (B, n, 16) at frames t+1..t+n."""
        x = state0.float()
        out = []
        for k in range(actions.shape[1]):
            features = torch.cat([self.normalise_states(x), actions[:, k] * 2 - 1], dim=-1)  # (B, 24)
            x = step(x, self.increments(features), self.config.dt, self.config.coasting)
            out.append(x)
        return torch.stack(out, dim=1)

    @classmethod
    def from_pretrained(cls, run_dir: str | Path, device: str | torch.device = "cpu") -> "StateDynamics":
        """The reference trained by ``orbitmodel probe RUN DATASET --state-only``, in eval mode."""
        return from_run(cls, run_dir, "state", device)


def constant_velocity(state0: torch.Tensor, n: int, dt: float = S.DT) -> torch.Tensor:
    """state0 (B, 16) -> states (B, n, 16): coasting, i.e. the coasting integrator with zero
    increments (world velocity, body rates and fuel held; R_k = R_0 exp(w dt)^k)."""
    return integrate(state0, state0.new_zeros(len(state0), n, INCREMENT_DIM), dt, coasting=True)
