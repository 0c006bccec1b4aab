"""The causal latent predictor with AdaLN-Zero action conditioning (DiT's block, made causal).

Position t of the sequence holds z_t and is modulated by the embedding of a_t; its output,
after the final LayerNorm and the projector, is the prediction of z_{t+1}. The causal mask keeps
every prediction blind to later frames and actions.
"""

from __future__ import annotations

import torch
from torch import nn

from orbitmodel.config import ModelConfig
from orbitmodel.model.vit import Attention, Mlp


def modulate(x: torch.Tensor, shift: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    return x * (1 + scale) + shift


class AdaLNBlock(nn.Module):
    """Pre-norm transformer block whose norms' shift, scale and residual gates come from the condition."""

    def __init__(self, dim: int, heads: int, mlp: int, dropout: float):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, elementwise_affine=False, eps=1e-6)
        self.attn = Attention(dim, heads, dropout)
        self.norm2 = nn.LayerNorm(dim, elementwise_affine=False, eps=1e-6)
        self.mlp = Mlp(dim, mlp, dropout)
        self.adaln = nn.Sequential(nn.SiLU(), nn.Linear(dim, 6 * dim))

    def forward(
        self, x: torch.Tensor, c: torch.Tensor, mod: torch.Tensor | None = None, last: bool = False
    ) -> torch.Tensor:
        """x, c: (B, T, D) -> (B, T, D). ``mod`` (B, T, 6D), optional: ``self.adaln(c)`` computed
        beforehand (a rollout computes it once for the whole horizon, not at every step). ``last``:
        the last position's output alone, (B, 1, D), as an imagined step needs it."""
        mod = self.adaln(c) if mod is None else mod
        shift_msa, scale_msa, gate_msa, shift_mlp, scale_mlp, gate_mlp = mod.chunk(6, dim=-1)
        y = self.attn(modulate(self.norm1(x), shift_msa, scale_msa), causal=True, last=last)
        if last:
            x, gate_msa, shift_mlp, scale_mlp, gate_mlp = (
                t[:, -1:] for t in (x, gate_msa, shift_mlp, scale_mlp, gate_mlp)
            )
        x = x + gate_msa * y
        return x + gate_mlp * self.mlp(modulate(self.norm2(x), shift_mlp, scale_mlp))


class Predictor(nn.Module):
    """(z (B, T, D), action embeddings (B, T, D)) -> next-latent features (B, T, D)."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        c = config
        self.pos = nn.Parameter(torch.zeros(1, c.max_seq_len, c.latent_dim))
        self.drop = nn.Dropout(c.pred_dropout)
        self.blocks = nn.ModuleList(
            AdaLNBlock(c.latent_dim, c.pred_heads, c.pred_mlp, c.pred_dropout) for _ in range(c.pred_depth)
        )
        self.norm = nn.LayerNorm(c.latent_dim)

    def modulations(self, cond: torch.Tensor) -> list[torch.Tensor]:
        """Every block's AdaLN shift/scale/gate for action embeddings cond (B, T, D): [(B, T, 6D)]."""
        return [block.adaln(cond) for block in self.blocks]

    def forward(
        self, z: torch.Tensor, cond: torch.Tensor | None, mods: list[torch.Tensor] | None = None, last: bool = False
    ) -> torch.Tensor:
        """z (B, T, D) and cond (B, T, D), or ``mods`` = ``self.modulations(cond)`` sliced to the
        same T frames, -> features (B, T, D); with ``last`` the last frame's alone, (B, 1, D)."""
        T = z.shape[1]
        if T > self.pos.shape[1]:
            raise ValueError(
                f"a sequence of {T} steps: the predictor takes at most {self.pos.shape[1]} (the preset's "
                "max_seq_len); give shorter windows"
            )
        x = self.drop(z + self.pos[:, :T])
        final = len(self.blocks) - 1
        for i, block in enumerate(self.blocks):
            x = block(x, cond, None if mods is None else mods[i], last=last and i == final)
        return self.norm(x)
