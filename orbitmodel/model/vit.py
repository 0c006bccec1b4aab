"""A plain ViT encoder (Dosovitskiy et al.), written out so no torchvision or timm is needed.

Pre-norm blocks, a CLS token, learned positional embeddings, a final LayerNorm; it returns the
CLS token and the patch tokens, as upstream's ``ViTModel(...).last_hidden_state`` split does.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from orbitmodel.config import ModelConfig


def causal_window_attention(qkv: torch.Tensor, last: bool = False) -> torch.Tensor:
    """Causal attention over a window of one or two tokens, written out: qkv (B, N, 3, h, d), N <= 2
    -> (B, N, h, d), or (B, 1, h, d) for the last position only.

    The planner's rollouts slide a window of two latents, where ``scaled_dot_product_attention``'s
    fixed cost per call outweighs its arithmetic. The first position sees itself only (its output is
    its value); the second weighs the two values by the softmax of two scores, which is the sigmoid
    of their difference. The same function as the kernel, to float rounding."""
    v = qkv[:, :, 2]
    if qkv.shape[1] == 1:
        return v
    q1, k = qkv[:, 1, 0], qkv[:, :, 1]
    w = torch.sigmoid((q1 * (k[:, 1] - k[:, 0])).sum(-1, keepdim=True) * q1.shape[-1] ** -0.5)  # (B, h, 1)
    second = torch.lerp(v[:, 0], v[:, 1], w)
    return second.unsqueeze(1) if last else torch.stack([v[:, 0], second], 1)


class Attention(nn.Module):
    """Multi-head self-attention through ``scaled_dot_product_attention``; in eval mode a causal
    window of at most two tokens goes through :func:`causal_window_attention`."""

    def __init__(self, dim: int, heads: int, dropout: float = 0.0):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)
        self.dropout = dropout

    def forward(self, x: torch.Tensor, causal: bool = False, last: bool = False) -> torch.Tensor:
        """x (B, N, C) -> (B, N, C); with ``last`` (causal only) the last position's output alone, (B, 1, C)."""
        B, N, C = x.shape
        qkv = self.qkv(x).view(B, N, 3, self.heads, C // self.heads)
        if causal and N <= 2 and not self.training:
            y = causal_window_attention(qkv, last)  # (B, N or 1, h, C/h)
            return self.proj(y.reshape(B, y.shape[1], C))
        q, k, v = qkv.permute(2, 0, 3, 1, 4)  # 3 x (B, h, N, C/h)
        if last:  # the last query sees every key: no mask needed
            q, causal = q[:, :, -1:], False
        y = F.scaled_dot_product_attention(
            q, k, v, is_causal=causal, dropout_p=self.dropout if self.training else 0.0
        )  # (B, h, N or 1, C/h)
        return self.proj(y.transpose(1, 2).reshape(B, y.shape[2], C))


class Mlp(nn.Sequential):
    def __init__(self, dim: int, hidden: int, dropout: float = 0.0):
        super().__init__(
            nn.Linear(dim, hidden), nn.GELU(), nn.Dropout(dropout), nn.Linear(hidden, dim), nn.Dropout(dropout)
        )


class Block(nn.Module):
    def __init__(self, dim: int, heads: int, mlp: int):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = Attention(dim, heads)
        self.norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = Mlp(dim, mlp)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x + self.attn(self.norm1(x))
        return x + self.mlp(self.norm2(x))


class ViT(nn.Module):
    """Images (B, 3, S, S) float in [0, 1] -> CLS (B, width) and patches (B, grid*grid, width)."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        c = config
        self.patch = nn.Conv2d(3, c.width, kernel_size=c.patch_size, stride=c.patch_size)
        self.cls = nn.Parameter(torch.zeros(1, 1, c.width))
        self.pos = nn.Parameter(torch.zeros(1, 1 + c.grid * c.grid, c.width))
        self.blocks = nn.ModuleList(Block(c.width, c.heads, c.mlp) for _ in range(c.depth))
        self.norm = nn.LayerNorm(c.width, eps=1e-6)
        self.image_size = c.image_size

    def forward(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        assert images.shape[-1] == self.image_size, f"expected {self.image_size} px images, got {tuple(images.shape)}"
        x = self.patch(images).flatten(2).transpose(1, 2)  # (B, P, width)
        x = torch.cat([self.cls.expand(len(x), -1, -1), x], dim=1) + self.pos  # (B, 1 + P, width)
        for block in self.blocks:
            x = block(x)
        x = self.norm(x)
        return x[:, 0], x[:, 1:]
