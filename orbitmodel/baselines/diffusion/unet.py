"""ConditionalUnet1D: Diffusion Policy's 1-D temporal U-Net over an action sequence, FiLM-conditioned.

    x (B, H, A) noisy actions, k (B,) diffusion step, c (B, C) observation features
    g = [StepEmbed(k), c]                                       (B, E + C)  global condition
    down: 2 residual blocks per level, then Conv1d(3, stride 2) except at the last level
    mid:  2 residual blocks at the widest level
    up:   concat the skip, 2 residual blocks, ConvTranspose1d(4, stride 2)
    out:  Conv1dBlock -> Conv1d(1) back to A channels           (B, H, A)  the noise or the clean sample

Every residual block is conv -> FiLM(g) -> conv, plus a 1x1 residual. As in the reference
(``real-stanford/diffusion_policy``, ``conditional_unet1d.py`` with ``cond_predict_scale``),
FiLM is ``scale * h + bias`` with both predicted from g, and the layers keep PyTorch's default
initialisation.
"""

from __future__ import annotations

import math

import torch
from torch import nn


def film(h: torch.Tensor, scale: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """Feature-wise linear modulation (Perez et al. 2018): h (B, C, H), scale and bias (B, C, 1)."""
    return scale * h + bias


class StepEmbedding(nn.Module):
    """Diffusion step k -> sinusoidal features -> MLP (4x wide, Mish), as in the reference."""

    def __init__(self, dim: int):
        super().__init__()
        if dim % 2:
            raise ValueError(f"step_embed={dim} must be even (sine and cosine halves)")
        self.dim = dim
        self.mlp = nn.Sequential(nn.Linear(dim, 4 * dim), nn.Mish(), nn.Linear(4 * dim, dim))

    def forward(self, k: torch.Tensor) -> torch.Tensor:  # (B,) -> (B, dim)
        half = self.dim // 2
        freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=k.device) / max(half - 1, 1))  # (half,)
        angles = k.float()[:, None] * freqs[None]  # (B, half)
        return self.mlp(torch.cat([angles.sin(), angles.cos()], dim=-1))


class Conv1dBlock(nn.Sequential):
    """Conv1d -> GroupNorm -> Mish, length preserving."""

    def __init__(self, c_in: int, c_out: int, kernel_size: int, n_groups: int):
        super().__init__(
            nn.Conv1d(c_in, c_out, kernel_size, padding=kernel_size // 2), nn.GroupNorm(n_groups, c_out), nn.Mish()
        )


class ConditionalResidualBlock1D(nn.Module):
    def __init__(self, c_in: int, c_out: int, cond_dim: int, kernel_size: int, n_groups: int):
        super().__init__()
        self.conv1 = Conv1dBlock(c_in, c_out, kernel_size, n_groups)
        self.conv2 = Conv1dBlock(c_out, c_out, kernel_size, n_groups)
        self.modulation = nn.Sequential(nn.Mish(), nn.Linear(cond_dim, 2 * c_out))  # per-channel scale, bias
        self.residual = nn.Conv1d(c_in, c_out, 1) if c_in != c_out else nn.Identity()

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:  # (B, c_in, H), (B, cond) -> (B, c_out, H)
        scale, bias = self.modulation(cond).unsqueeze(-1).chunk(2, dim=1)  # (B, c_out, 1) each
        h = film(self.conv1(x), scale, bias)  # (B, c_out, H)
        return self.conv2(h) + self.residual(x)


class ConditionalUnet1D(nn.Module):
    """Denoises a (B, H, A) action sequence given the step and global features: predicts its noise
    or its clean sample, as the policy's ``prediction_type`` trains it."""

    def __init__(
        self,
        action_dim: int,
        global_cond_dim: int,
        down_dims: tuple[int, ...],
        step_embed: int,
        kernel_size: int,
        n_groups: int,
    ):
        super().__init__()
        self.step_embedding = StepEmbedding(step_embed)
        cond = step_embed + global_cond_dim

        def block(c_in: int, c_out: int) -> ConditionalResidualBlock1D:
            return ConditionalResidualBlock1D(c_in, c_out, cond, kernel_size, n_groups)

        dims = (action_dim, *down_dims)
        pairs = list(zip(dims[:-1], dims[1:]))  # (c_in, c_out) per level
        self.down = nn.ModuleList()
        for i, (c_in, c_out) in enumerate(pairs):
            last = i == len(pairs) - 1
            self.down.append(
                nn.ModuleList(
                    [
                        block(c_in, c_out),
                        block(c_out, c_out),
                        nn.Identity() if last else nn.Conv1d(c_out, c_out, 3, 2, 1),
                    ]
                )
            )
        self.mid = nn.ModuleList([block(down_dims[-1], down_dims[-1]), block(down_dims[-1], down_dims[-1])])
        self.up = nn.ModuleList()
        for c_in, c_out in reversed(pairs[1:]):  # c_out: this level's width; c_in: the level above's
            self.up.append(
                nn.ModuleList([block(2 * c_out, c_in), block(c_in, c_in), nn.ConvTranspose1d(c_in, c_in, 4, 2, 1)])
            )
        self.final = nn.Sequential(
            Conv1dBlock(down_dims[0], down_dims[0], kernel_size, n_groups), nn.Conv1d(down_dims[0], action_dim, 1)
        )

    def forward(self, sample: torch.Tensor, step: torch.Tensor, global_cond: torch.Tensor) -> torch.Tensor:
        """sample (B, H, A), step (B,) int, global_cond (B, C) -> (B, H, A), the noise or the clean sample."""
        g = torch.cat([self.step_embedding(step), global_cond], dim=-1)  # (B, E + C)
        x = sample.transpose(1, 2)  # (B, A, H): convolve over time
        skips = []
        for res1, res2, downsample in self.down:
            x = res2(res1(x, g), g)
            skips.append(x)
            x = downsample(x)  # (B, c, H / 2) except at the last level
        for res in self.mid:
            x = res(x, g)
        for res1, res2, upsample in self.up:
            x = torch.cat([x, skips.pop()], dim=1)  # (B, 2c, h)
            x = upsample(res2(res1(x, g), g))  # (B, c_above, 2h)
        return self.final(x).transpose(1, 2)  # (B, H, A)
