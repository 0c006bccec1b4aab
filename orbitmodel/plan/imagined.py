"""Debris where the world model imagines them (issue 40's way (a)): depth read from imagined latents.

The world model rolls each MPPI candidate's latents forward one predictor step (``frame_step``
frames) at a time. :class:`ImaginedDepthHead` reads a latent, observed or imagined, as a 16x16
z-depth map (fitted on the frozen world model's own rollouts: ``plan.imagined_fit``), so each
candidate carries its own picture of where the debris will be at each step, as seen from where
the probe puts the body then. :class:`ImaginedField` back-projects those maps through the camera
from the candidate's imagined poses and answers the cost's clearance query: frame h of the plan
(frame t+h+1) meets the map of predictor step h // s (frame t+(h//s+1) s, the first step at or
after it).

The camera sees only ahead. What the planner saw earlier and no longer sees (a piece of debris it
passed, one at the side) stays in the point memory, still, and the field adds the memory's points
outside the current view (:func:`outside_view`); what is in view is the imagined maps' alone,
so a piece of debris seen moving is not also planned around where it was.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from orbitdata.schema import DEPTH_LOW_SIDE
from orbitmodel.kinematics import ROT, P, rot6d_to_matrix
from orbitmodel.plan.obstacles import Camera, PointCloud


class ImaginedDepthHead(nn.Module):
    """latent (..., D) -> z-depth (..., 16, 16) as a fraction of the run's depth scale (the far plane).

    An MLP on the latent alone: the predictor imagines latents, not the ViT's patch tokens that
    the frame's depth head reads, so this head is what turns an imagined future into geometry.
    """

    def __init__(self, latent_dim: int, hidden: int = 512, side: int = DEPTH_LOW_SIDE):
        super().__init__()
        self.latent_dim, self.hidden, self.side = int(latent_dim), int(hidden), int(side)
        self.net = nn.Sequential(
            nn.Linear(latent_dim, hidden),
            nn.GELU(),
            nn.Linear(hidden, hidden),
            nn.GELU(),
            nn.Linear(hidden, side * side),
        )

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self.net(z)).unflatten(-1, (self.side, self.side))


class ImaginedDepth:
    """A fitted :class:`ImaginedDepthHead` and the run's depth scale: latents -> metres."""

    def __init__(self, head: ImaginedDepthHead, scale: float, timings=None):
        self.head, self.scale, self.timings = head.eval(), float(scale), timings

    @torch.inference_mode()
    def maps(self, z: torch.Tensor) -> torch.Tensor:
        """(..., D) latents -> (..., 16, 16) z-depth, metres."""
        return self.head(z.float()) * self.scale


def outside_view(points: np.ndarray, state: np.ndarray, camera: Camera, max_range: float) -> np.ndarray:
    """(N,) bool: the world ``points`` (N, 3) the camera at ``state`` (16,) does not see now: behind
    it, outside the image's field of view, or beyond ``max_range`` of z-depth."""
    s = np.asarray(state, dtype=np.float64)
    R = rot6d_to_matrix(torch.as_tensor(s[ROT])).numpy()  # body -> world
    rotation = np.asarray(camera.rotation)  # camera -> body
    cam = ((np.asarray(points, dtype=np.float64) - s[P]) @ R - np.asarray(camera.position)) @ rotation  # camera frame
    depth = -cam[:, 2]  # MuJoCo's camera looks along its -z
    half = math.tan(math.radians(camera.fovy_deg) / 2)
    inside = (
        (depth > 0) & (depth < max_range) & (np.abs(cam[:, 0]) <= half * depth) & (np.abs(cam[:, 1]) <= half * depth)
    )
    return ~inside


class ImaginedField:
    """Per-candidate obstacles from the depth maps each candidate imagines, plus a still ``base``.

    Args:
        maps: (K, S, 16, 16) z-depth, metres: candidate k's map at predictor step j.
        states: (K, H, 16) the candidates' imagined states, frames t+1..t+H (H = S x step).
        step: frames per predictor step.
        camera: the pinhole model that back-projects the maps.
        max_range: metres; cells at or beyond it (or the far plane) are no obstacle.
        footprint: each cell's sphere is ``footprint`` x half the cell's width at its depth
            (``obstacles.depth_to_points``' convention).
        base: a field of still obstacles (the point memory outside the current view), or None.
    """

    def __init__(
        self,
        maps: torch.Tensor,
        states: torch.Tensor,
        step: int,
        camera: Camera,
        max_range: float,
        footprint: float = 1.0,
        base: PointCloud | None = None,
    ):
        K, S, side, _ = maps.shape
        if states.shape[1] != S * step:
            raise ValueError(f"{states.shape[1]} imagined frames are not {S} steps of {step} frames")
        self.step, self.base = int(step), base
        maps = maps.float()
        rays = torch.as_tensor(camera.cell_rays(side), dtype=torch.float32).reshape(-1, 3)  # (C, 3) unit z-depth
        d = maps.reshape(K, S, -1)  # (K, S, C)
        self.keep = torch.isfinite(d) & (d > 0) & (d < min(max_range, 0.99 * camera.far))  # (K, S, C)
        d = torch.where(self.keep, d, torch.zeros_like(d))
        body = torch.as_tensor(camera.position, dtype=torch.float32) + d[..., None] * rays  # (K, S, C, 3)
        seen_from = states[:, step - 1 :: step].float()  # (K, S, 16): the pose at the end of each step
        R = rot6d_to_matrix(seen_from[..., ROT])  # (K, S, 3, 3) body -> world
        self.points = seen_from[..., None, P] + body @ R.transpose(-1, -2)  # (K, S, C, 3) world
        self.radii = footprint * 0.5 * camera.cell_width(side) * d  # (K, S, C)

    def clearance(self, positions: torch.Tensor, times: torch.Tensor | None = None) -> torch.Tensor:
        """(K, H, 3) metres -> (K, H) to the nearest imagined surface at frame h (its step's map)
        or the base's points. The imagined maps carry their own time: ``times`` is not read."""
        K, H, _ = positions.shape
        j = (torch.arange(H) // self.step).clamp(max=self.points.shape[1] - 1)  # (H,) each frame's step
        gap = (positions.float()[:, :, None] - self.points[:, j]).norm(dim=-1) - self.radii[:, j]  # (K, H, C)
        gap = torch.where(self.keep[:, j], gap, torch.full_like(gap, math.inf))
        out = gap.amin(-1) if gap.shape[-1] else torch.full((K, H), math.inf)
        if self.base is not None and len(self.base):
            out = torch.minimum(out, self.base.clearance(positions))
        return out
