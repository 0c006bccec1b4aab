"""One encoder pass per observed frame, shared by the planner's two readings of it.

The learned planner reads each new camera frame twice: the world model's latent (``encode``:
the ViT's CLS token with the state) and the depth head's 16x16 map (the ViT's patch tokens).
Both come from the same ViT forward pass: :func:`encode_frames` runs it once for a batch of
frames (the lockstep flights' N episodes, ``plan.batch``), and :class:`FrameEncoder` keeps the
result for the one frame it was given (keyed on the image's bytes, so a reused buffer holding a
new frame is encoded again). Same numbers as encoding twice: the same op on the same input.
"""

from __future__ import annotations

import numpy as np
import torch

from orbitmodel.model.world_model import images_to_float
from orbitmodel.plan.timing import Timings


@torch.inference_mode()
def encode_frames(model, images: list[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
    """``images`` N x (H, W, 3) uint8 -> the ViT's (cls (N, width), patches (N, P, width)), one pass."""
    size = model.config.image_size
    shape = np.shape(images[0])
    if shape != (size, size, 3):
        raise ValueError(
            f"the camera gives images of shape {shape}; this world model takes ({size}, {size}, 3): fly it in the "
            "SimConfig that build_pilot returns with the pilot (pilot, sim = build_pilot(...); CubeSatEnv(sim))"
        )
    # Channels first in memory, whatever N: a channels-last batch sends the patch convolution down
    # another kernel, whose sums differ from a lone frame's in the last bit, and a lockstep episode
    # would then part from its unbatched flight.
    x = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).contiguous()  # (N, 3, H, W)
    return model.encoder(images_to_float(x))


class FrameEncoder:
    """``frames(image (H, W, 3) uint8) -> (cls (1, width), patches (1, P, width))`` of a world model,
    computed once per distinct frame."""

    def __init__(self, model):
        self.model = model
        self._key: tuple | None = None
        self._out: tuple[torch.Tensor, torch.Tensor] | None = None

    def __call__(self, image: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        raw = np.ascontiguousarray(image)
        key = (raw.shape, raw.dtype.str, raw.tobytes())
        if key != self._key:
            self._out = encode_frames(self.model, [raw])
            self._key = key
        return self._out


class PredictedDepth:
    """A depth head on the current frame: observation -> (16, 16) z-depth, metres.

    ``head``: the refitted head (``orbitmodel depth``); None for the one trained in Stage I.
    ``name``: what the pilot's metadata calls it (stage1, refit, refit-NAME; by default from ``head``).
    ``frames``: the encoder pass shared with the learned dynamics: the frame's ViT pass is then
    timed under "encode", where the dynamics ran it first, and "depth-head" is the head alone.
    :meth:`maps` reads the patch tokens of a batch of frames encoded already (``plan.batch``).
    """

    def __init__(
        self, model, timings: Timings | None = None, head=None, frames: FrameEncoder | None = None, name: str = ""
    ):
        self.model = model.eval()
        self.timings = timings or Timings()
        self.head = head
        self.frames = frames or FrameEncoder(self.model)
        self.name = name or ("stage1" if head is None else "refit")

    @torch.inference_mode()
    def __call__(self, obs: dict) -> np.ndarray:
        with self.timings("depth-head"):
            _, patches = self.frames(obs["image"])  # (1, P, width)
            return self.model.depth_from_patches(patches, self.head)[0].numpy()  # (16, 16) metres

    @torch.inference_mode()
    def maps(self, patches: torch.Tensor) -> np.ndarray:
        """The ViT's patch tokens (N, P, width) of N frames -> (N, 16, 16) z-depth, metres."""
        with self.timings("depth-head"):
            return self.model.depth_from_patches(patches, self.head).numpy()
