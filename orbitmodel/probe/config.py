"""The probe network's config: a Stage I preset's probe recipe (``orbitmodel.config.ProbeRecipe``)
made concrete for one world model (its latent size and the seconds per model step).

Upstream (configs/stage2.yaml): MLP 256 -> 256 -> GELU -> 256 -> GELU -> 10, reading the
latents, integrating p += dp, v += dv.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from orbitdata import schema as S
from orbitmodel.config import INPUTS, INTEGRATORS, KINDS, modulates_thrust, reads_latent, reads_thrust


@dataclass(frozen=True)
class ProbeConfig:
    """The probe MLP (and the state-only reference, which has the same body).

    Args:
        kind: "latent": reads a world model's imagined latents; "state": reads (state, action).
        latent_dim: the world model's z size (latent kind) or 16 + 8 (state kind).
        hidden, layers: ``layers`` hidden layers of ``hidden`` units with GELU, then 10 outputs.
        dt: seconds per integration step (a latent step's / ``substeps``); the attitude integrates exp(w' dt).
        inputs: "latent" (upstream): the MLP reads z_k. "latent+change": it reads [z_k, z_k - z_{k-1}]
            (z_0 the last context latent): the world model predicts the change of z, and the
            increments are about change. "thrust": no latent at all, only each step's thrusts
            (the thrust-only reference: the latents are given and ignored).
        integrator: "upstream": p' = p + dp, v' = v + dv. "coasting": zero increments hold the
            world-frame velocity and the position follows it; the increments are what thrust
            changes (see ``probe.integrator``).
        substeps: increments per latent step, each integrated over ``dt``: 1 gives one state per
            latent; a world model stepping s frames with ``substeps = s`` gives every frame's state
            (the per-frame head), with nothing interpolated between its latents.
        action_dim: the width of one step's action (8 s thrusts); read with
            ``inputs = "latent+change+thrust"``, by a branch of its own whose increments add to the
            latent branch's.
    """

    kind: str = "latent"
    latent_dim: int = 256
    hidden: int = 256
    layers: int = 2
    dt: float = S.DT
    inputs: str = "latent"
    integrator: str = "upstream"
    substeps: int = 1
    action_dim: int = 0

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"probe kind {self.kind!r}: choose one of {', '.join(KINDS)}")
        if self.inputs not in INPUTS or (self.kind == "state" and self.inputs != "latent"):
            raise ValueError(
                f"inputs {self.inputs!r}: choose one of {', '.join(INPUTS)} (the state kind reads its own)"
            )
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"integrator {self.integrator!r}: choose one of {', '.join(INTEGRATORS)}")
        if self.layers < 1 or self.hidden < 1:
            raise ValueError(f"layers={self.layers}, hidden={self.hidden}: give at least one hidden layer")
        if self.reads_thrust and self.action_dim < 1:
            raise ValueError(f"inputs {self.inputs!r} reads each step's thrusts: give action_dim (8 per frame)")
        if self.substeps < 1 or (self.kind == "state" and self.substeps != 1):
            raise ValueError(f"substeps={self.substeps}: give 1 or more (the state kind predicts one per step)")

    @property
    def coasting(self) -> bool:
        return self.integrator == "coasting"

    @property
    def reads_change(self) -> bool:
        return self.inputs.startswith("latent+change")

    @property
    def reads_thrust(self) -> bool:
        return reads_thrust(self.inputs)

    @property
    def reads_latent(self) -> bool:
        return reads_latent(self.inputs)

    @property
    def modulates_thrust(self) -> bool:
        return modulates_thrust(self.inputs)

    @property
    def dims(self) -> tuple[int, ...]:
        """The latent branch's MLP: its features -> 10 increments per substep (a probe reading no
        latent has none)."""
        d_in = 2 * self.latent_dim if self.reads_change else self.latent_dim
        return (d_in, *([self.hidden] * self.layers), 10 * self.substeps)

    @property
    def thrust_dims(self) -> tuple[int, ...]:
        """The thrust branch's MLP (a probe reading thrusts): a step's thrusts -> the same outputs."""
        return (self.action_dim, *([self.hidden] * self.layers), 10 * self.substeps)

    def to_dict(self) -> dict:
        return asdict(self)
