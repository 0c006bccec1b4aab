"""One encoder pass per observed frame, shared by the planner's two readings of it.

The learned planner reads each new camera frame twice: the world model's latent (``encode``:
the ViT's CLS token with the state) and the depth head's 16x16 map (the ViT's patch tokens).
Both come from the same ViT forward pass, so :class:`FrameEncoder` runs it once and keeps the
result for the frame it was given (keyed on the image's bytes, so a reused buffer holding a new
frame is encoded again). Same numbers as encoding twice: the same op on the same input.
"""

from __future__ import annotations

import numpy as np
import torch

from orbitmodel.model.world_model import images_to_float


class FrameEncoder:
    """``frames(image (H, W, 3) uint8) -> (cls (1, width), patches (1, P, width))`` of a world model,
    computed once per distinct frame."""

    def __init__(self, model):
        self.model = model
        self._key: tuple | None = None
        self._out: tuple[torch.Tensor, torch.Tensor] | None = None

    @torch.inference_mode()
    def __call__(self, image: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        raw = np.ascontiguousarray(image)
        key = (raw.shape, raw.dtype.str, raw.tobytes())
        if key != self._key:
            x = torch.from_numpy(raw).permute(2, 0, 1)[None]  # (1, 3, H, W)
            self._out = self.model.encoder(images_to_float(x))
            self._key = key
        return self._out
