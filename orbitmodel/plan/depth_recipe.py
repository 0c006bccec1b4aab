"""The depth heads' recipes (``orbitmodel depth``, ``--imagined``), and the planner's range, free of
torch: the CLI shows the defaults without loading the model code (``plan.depth_refit`` and
``plan.imagined_fit`` fit them)."""

from __future__ import annotations

import re
from dataclasses import dataclass

from orbitmodel.data import EVAL_SPLITS

MAX_RANGE = 10.0  # metres: depth cells farther than this are no obstacle to plan around
# the planner's depth_head choices that name no head of their own (PlannerConfig.depth_head)
CHOICES = ("auto", "stage1", "refit")
HEAD_NAME = re.compile(r"[a-z0-9][a-z0-9_]*")
FOLDER = "depth"  # RUN/depth: the run's refitted head; RUN/depth-NAME: one refitted under a name


def is_head_name(name: str) -> bool:
    """Can ``name`` name a refitted head (RUN/depth-NAME)?"""
    return bool(HEAD_NAME.fullmatch(name)) and name not in CHOICES and name != "imagined"


def head_folder(name: str = "") -> str:
    """The folder in a run of the refitted head named ``name`` ("": the run's own, RUN/depth)."""
    return f"{FOLDER}-{check_head_name(name)}" if name else FOLDER


def head_name(folder: str) -> str | None:
    """The name of the head a run's sub-folder ``folder`` holds (RUN/depth-NAME), or None if no name gives it."""
    name = folder.removeprefix(f"{FOLDER}-")
    return name if name != folder and is_head_name(name) else None


def check_head_name(name: str) -> str:
    """``name`` if it can name a refitted head (RUN/depth-NAME), else ValueError saying what can."""
    if not is_head_name(name):
        raise ValueError(
            f"depth head name {name!r}: use lower-case letters, digits and _ (not {', '.join(CHOICES)} or "
            "imagined), e.g. dynamic for a head refitted on the dynamic tier's frames"
        )
    return name


def check_fit(cfg) -> None:
    """The checks both recipes share: their optimisation (epochs, batch_size, lr), the near-cell
    weighting (near_weight, near_m) and the split they are scored on (ValueError naming the field)."""
    if min(cfg.epochs, cfg.batch_size) < 1:
        raise ValueError("epochs and batch_size must be >= 1")
    if cfg.eval_split not in EVAL_SPLITS:
        raise ValueError(f"eval_split={cfg.eval_split!r}: choose one of {', '.join(EVAL_SPLITS)}")
    if not (cfg.lr > 0 and cfg.near_weight >= 0 and cfg.near_m > 0):
        raise ValueError(f"lr={cfg.lr} and near_m={cfg.near_m} must be > 0, near_weight={cfg.near_weight} >= 0")


@dataclass(frozen=True)
class DepthRefitConfig:
    """The refit's recipe (``docs/planner.md`` gives the comparison it was chosen from; the fit
    holds ``frames`` x patches x width float16 tokens in memory).

    Args:
        frames: random training frames whose patch tokens are encoded once (a dataset with fewer
            training frames needs ``--frames``; the 3000-episode 64 px dataset has ~330,000).
        test_frames: random frames of ``eval_split`` for the before/after comparison.
        eval_split: "test" (to report) or "val": the run's validation episodes (to choose a recipe).
        epochs, batch_size, lr: AdamW on the head alone, cosine decay to zero.
        near_weight: extra weight of a cell whose true depth is below ``near_m``.
        near_m: metres; the planner's range (``plan.config.MAX_RANGE``).
        seed: frame choice and data order.
    """

    frames: int = 120000
    test_frames: int = 4000
    epochs: int = 30
    batch_size: int = 256
    lr: float = 1e-3
    near_weight: float = 25.0
    near_m: float = MAX_RANGE
    seed: int = 0
    eval_split: str = "test"

    def __post_init__(self):
        if min(self.frames, self.test_frames) < 1:
            raise ValueError("frames and test_frames must be >= 1")
        check_fit(self)


@dataclass(frozen=True)
class ImaginedDepthConfig:
    """The fit's recipe.

    Args:
        windows: random training windows imagined once (each gives 1 + horizon / step latents).
        test_windows: random windows of ``eval_split`` scored before and after.
        context: encoded frames' latents the rollout starts from (the ``cpu`` planner's history).
        horizon: frames imagined (the planner's horizon; a multiple of the run's frame step).
        hidden: the head's width.
        epochs, batch_size, lr: AdamW on the head alone, cosine decay to zero.
        near_weight, near_m: the refit's weighting of the cells nearer than ``near_m`` metres.
        seed: window choice, initialisation and data order.
        eval_split: "test" (to report) or "val", the run's validation episodes (to choose).
    """

    windows: int = 6000
    test_windows: int = 400
    context: int = 2
    horizon: int = 50
    hidden: int = 512
    epochs: int = 30
    batch_size: int = 256
    lr: float = 1e-3
    near_weight: float = 25.0
    near_m: float = MAX_RANGE
    seed: int = 0
    eval_split: str = "test"

    def __post_init__(self):
        if min(self.windows, self.test_windows, self.context, self.horizon, self.hidden) < 1:
            raise ValueError("windows, test_windows, context, horizon and hidden must be >= 1")
        check_fit(self)
