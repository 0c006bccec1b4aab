"""How the inferred body's prior is trained (``orbitmodel body``; ``plan.inferred_body``).

Kept apart from the training code so that the CLI reads its defaults without importing torch.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class InferenceConfig:
    """How :class:`BodyInference` is trained.

    Args:
        frames: the most history frames it is shown (the fit's ``fit_frames``); each training cut
            draws a length from 0 to this.
        ahead: frames after the cut whose changes it must predict from their thrusts.
        ridge: the ridge of the least-squares fit whose solution it reads (and flies with).
        max_rate: rad/s; only cuts where the body turns at most this fast are trained on (the
            planner's probe's limit, ``cpu-step5-dynamic``).
        width: hidden units of its two layers.
        steps, batch, lr: AdamW steps, cuts per step and learning rate (cosine decay).
        seed: the generator of the cuts and the initial weights.
    """

    frames: int = 40
    ahead: int = 25
    ridge: float = 1e-5
    max_rate: float = 3.0
    width: int = 256
    steps: int = 1000
    batch: int = 512
    lr: float = 1e-3
    seed: int = 0
