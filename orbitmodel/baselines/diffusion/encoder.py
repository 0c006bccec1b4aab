"""The observation encoder: what the policy knows at frame t, as one feature vector.

For each of the last ``n_obs_steps`` observations (frames t-1, t)::

    f_i = [CNN(image_i), normalised state_i, goal in the body frame_i / goal scale]   (F + 16 + 3,)

and the global condition is their concatenation (B, n_obs_steps * (F + 19)), as in the
reference's ``obs_as_global_cond``; without images (``PolicyConfig.images`` False) F is 0. A
privileged diagnostic (``PolicyConfig.obstacles`` = K > 0) appends, per observation, K x 5 numbers:
each true obstacle's centre in the body frame and bounding radius (over the goal scale) and a 1
(zeros for an empty slot). The CNN stands in for the reference's ResNet18 with
GroupNorm: stride-2 3x3 convolutions with GroupNorm and Mish, then a linear map of the
flattened last feature map (which keeps where an obstacle is in the image).
"""

from __future__ import annotations

import torch
from torch import nn

from orbitmodel.baselines.diffusion.config import GOAL_DIM, PolicyConfig

OBSTACLE_DIM = 5  # per true obstacle of a privileged policy: centre (3, body frame), bounding radius, present


class ImageEncoder(nn.Module):
    """(B, 3, S, S) float in [-1, 1] -> (B, image_features)."""

    def __init__(self, config: PolicyConfig):
        super().__init__()
        layers: list[nn.Module] = []
        c_in = 3
        for c_out in config.cnn_channels:
            layers += [nn.Conv2d(c_in, c_out, 3, stride=2, padding=1), nn.GroupNorm(config.n_groups, c_out), nn.Mish()]
            c_in = c_out
        self.convs = nn.Sequential(*layers)
        side = config.image_size // 2 ** len(config.cnn_channels)
        self.head = nn.Linear(c_in * side * side, config.image_features)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.head(self.convs(images).flatten(1))  # (B, c, s, s) -> (B, F)


class ObservationEncoder(nn.Module):
    """Normalised observations over n_obs_steps -> the U-Net's global condition."""

    def __init__(self, config: PolicyConfig):
        super().__init__()
        self.image = ImageEncoder(config) if config.images else None
        features = config.image_features if config.images else 0
        self.out_dim = config.n_obs_steps * (features + config.state_dim + GOAL_DIM + OBSTACLE_DIM * config.obstacles)

    def forward(
        self,
        images: torch.Tensor | None,
        states: torch.Tensor,
        goal_body: torch.Tensor,
        obstacles_body: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """images (B, To, 3, S, S) in [-1, 1] (None without an image encoder); states (B, To, 16),
        goal_body (B, To, 3) and (a privileged policy's) obstacles_body (B, To, K, 5) normalised
        -> (B, To * (F + 19 + 5 K))."""
        parts = [states, goal_body]
        if obstacles_body is not None:
            parts.append(obstacles_body.flatten(2))
        if self.image is not None:
            B, To = images.shape[:2]
            parts.insert(0, self.image(images.flatten(0, 1)).view(B, To, -1))  # (B, To, F)
        return torch.cat(parts, dim=-1).flatten(1)
