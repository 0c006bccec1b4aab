"""What the model needs from an orbitdata dataset: its metadata (image size, normalisation,
camera) and windows cut through ``orbitdata.load_windows``.

DATASET is a local folder or a Hub repo id, exactly as ``load_windows`` takes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orbitdata import schema as S
from orbitdata.load.config import IS_PAD
from orbitdata.state import STATE_SLICES


@dataclass(frozen=True)
class DatasetMeta:
    """The facts a model run records about its training data."""

    source: str
    image_size: int
    state_mean: tuple[float, ...]  # (16,)
    state_std: tuple[float, ...]  # (16,)
    action_mean: tuple[float, ...]  # (8,)
    action_std: tuple[float, ...]  # (8,)
    depth_max: float  # metres: the far plane of depth_low
    fovy_deg: float
    root_seed: int
    episodes: dict  # split -> episode count

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, d: dict) -> "DatasetMeta":
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})


def read_dataset_meta(source: str | Path) -> DatasetMeta:
    """Info and stats of an orbitdata dataset; raises FileNotFoundError / ValueError with the fix."""
    from orbitdata.load import read_meta

    info, stats = read_meta(source)
    camera = info.config["sim"]["camera"]
    return DatasetMeta(
        source=str(source),
        image_size=int(info.image_size),
        state_mean=tuple(float(x) for x in stats[S.STATE]["mean"]),
        state_std=tuple(float(x) for x in stats[S.STATE]["std"]),
        action_mean=tuple(float(x) for x in stats[S.ACTION]["mean"]),
        action_std=tuple(float(x) for x in stats[S.ACTION]["std"]),
        depth_max=float(np.max(stats[S.DEPTH_LOW]["max"])),
        fovy_deg=float(camera["fovy_deg"]),
        root_seed=int(info.root_seed),
        episodes={split: int(c["episodes"]) for split, c in info.counts["splits"].items()},
    )


def episode_filter(levels: list[str] | None, outcomes: list[str] | None) -> dict | None:
    """The ``episodes=`` filter of ``load_windows`` for a level / outcome selection."""
    chosen = {}
    if levels:
        chosen[S.LEVEL] = list(levels)
    if outcomes:
        chosen[S.OUTCOME] = list(outcomes)
    return chosen or None


# ---- model steps of several frames (ModelConfig.frame_step) ------------------------------------
FLAG_KEYS = (S.COLLISION, IS_PAD)  # per-frame flags: a model step has one if any of its frames has
FRAME_STATES = "frame_states"  # not a dataset column: a model-step window's state at every frame (T s, 16)


def group_actions(actions, frame_step: int):
    """(..., T s, 8) per-frame thrusts -> (..., T, 8 s): each model step's s thrusts, concatenated
    in time order (the action a ``frame_step`` = s world model takes per step)."""
    if frame_step == 1:
        return actions
    *lead, frames, dim = actions.shape
    if frames % frame_step:
        raise ValueError(f"{frames} actions do not split into steps of {frame_step} frames")
    return actions.reshape(*lead, frames // frame_step, frame_step * dim)


def skip_frames(window: dict, frame_step: int, time_dim: int = 0) -> dict:
    """A window of T s frames (time on ``time_dim``) -> T model steps of s frames: each step's
    first frame (image, state, depth, ...), its s actions grouped (:func:`group_actions`), and
    per-frame flags (collision, padding) set when any of its frames has them."""
    if frame_step == 1:
        return window
    out = {}
    for key, value in window.items():
        if key == S.ACTION:
            out[key] = group_actions(value, frame_step)
        elif key in FLAG_KEYS:
            shape = value.shape
            out[key] = value.reshape(
                *shape[:time_dim], shape[time_dim] // frame_step, frame_step, *shape[time_dim + 1 :]
            ).any(time_dim + 1)
        else:
            out[key] = value[(slice(None),) * time_dim + (slice(None, None, frame_step),)]
    return out


class ModelStepWindows:
    """A ``WindowDataset`` of T s frames seen as windows of T model steps (:func:`skip_frames`);
    the loader's API (len, items, batches, ``sampler``) and its attributes pass through. With
    ``frame_states`` each window also keeps its state at every frame (``FRAME_STATES``, T s x 16):
    the targets of a probe that predicts every frame."""

    def __init__(self, frames, frame_step: int, frame_states: bool = False):
        self.frames, self.frame_step, self.frame_states = frames, frame_step, frame_states

    def __len__(self) -> int:
        return len(self.frames)

    def _steps(self, window: dict, time_dim: int) -> dict:
        out = skip_frames(window, self.frame_step, time_dim)
        if self.frame_states:
            out[FRAME_STATES] = window[S.STATE]
        return out

    def __getitem__(self, i: int) -> dict:
        return self._steps(self.frames[i], 0)

    def __getitems__(self, indices):
        from orbitdata.load.collate import WindowBatch

        batch = self.frames.__getitems__(indices)
        return WindowBatch(self._steps(batch.stacked, 1)) if len(batch) else batch

    def sampler(self, *args, **kwargs):
        return self.frames.sampler(*args, **kwargs)

    def __getattr__(self, name):
        if name == "frames":  # not set yet (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.frames, name)


def load_model_windows(
    source,
    frame_step: int = 1,
    context: int = 1,
    horizon: int = 0,
    stride: int = 1,
    frame_states: bool = False,
    **kwargs,
):
    """``orbitdata.load_windows`` counted in model steps: windows of ``context + horizon`` steps of
    ``frame_step`` frames each (``stride`` stays in frames); ``frame_states`` keeps every frame's
    state too (:class:`ModelStepWindows`). At ``frame_step`` 1 it is the loader's own dataset,
    unchanged."""
    from orbitdata.load import load_windows

    frames = load_windows(source, context=context * frame_step, horizon=horizon * frame_step, stride=stride, **kwargs)
    return frames if frame_step == 1 else ModelStepWindows(frames, frame_step, frame_states)


def calm_windows(windows, max_rate: float) -> list[int]:
    """Indices of the windows (a ``WindowDataset`` or :class:`ModelStepWindows`) whose body rate
    stays at or below ``max_rate`` rad/s at every real frame, in table order."""
    frames = getattr(windows, "frames", windows)
    column = frames.steps.data.table.column(S.STATE).combine_chunks()
    states = column.flatten().to_numpy(zero_copy_only=False).reshape(len(column), -1)
    fast = np.flatnonzero(np.linalg.norm(states[:, STATE_SLICES["w"]], axis=1) > max_rate)  # rows over the rate
    index = frames.index
    # the first fast row at or after each window's first row: the window is calm when it lies past the window
    at = np.searchsorted(fast, index.row)
    first_fast = np.append(fast, np.iinfo(np.int64).max)[at]
    return np.flatnonzero(first_fast >= index.row + index.n_real).tolist()


# ---- the validation split: held-out training episodes, where every choice is made ----------------
VAL = "val"  # a split name of orbitmodel's evaluations: the run's validation episodes of the train split
EVAL_SPLITS = (VAL, "test")


@dataclass(frozen=True)
class ValidationSplit:
    """A seeded fraction of the train split's episodes, held out of every training stage of a run
    (Stage I, the probe, the depth refit) and recorded in its config.json: choices (recipes,
    knobs, epochs) are made on these, the test split only reports."""

    fraction: float
    seed: int
    episodes: tuple[int, ...]

    def to_dict(self) -> dict:
        return {"fraction": self.fraction, "seed": self.seed, "episodes": list(self.episodes)}

    @classmethod
    def from_dict(cls, d: dict | None) -> "ValidationSplit":
        d = d or {"fraction": 0.0, "seed": 0, "episodes": []}
        return cls(float(d["fraction"]), int(d["seed"]), tuple(int(e) for e in d["episodes"]))


def validation_split(source, fraction: float, seed: int) -> ValidationSplit:
    """``fraction`` of the train split's episodes of every level (rounded, at least one per level
    when the fraction is > 0), drawn with a generator seeded by ``seed``: the same source, fraction
    and seed give the same episodes."""
    from orbitdata.load.tables import load_episode_table

    if not 0.0 <= fraction < 1.0:
        raise ValueError(f"validation fraction {fraction} must be in [0, 1)")
    if fraction == 0.0:
        return ValidationSplit(0.0, seed, ())
    table = load_episode_table(source, "train", {}).select([S.EPISODE_INDEX, S.LEVEL])
    index = table.column(S.EPISODE_INDEX).to_numpy().astype(np.int64)
    level = np.asarray(table.column(S.LEVEL).to_pylist())
    rng = np.random.default_rng(seed)
    chosen: list[int] = []
    for name in sorted(set(level)):  # per level, so the held-out mix is the training mix
        ids = np.sort(index[level == name])
        take = min(len(ids) - 1, max(1, round(fraction * len(ids))))
        chosen += rng.choice(ids, size=take, replace=False).tolist() if take > 0 else []
    return ValidationSplit(fraction, seed, tuple(sorted(int(e) for e in chosen)))


def training_episodes(source, levels, outcomes, held_out: ValidationSplit | None):
    """The ``episodes=`` filter of a training stage: the level / outcome selection without the
    run's validation episodes."""
    chosen = episode_filter(list(levels), list(outcomes))
    if held_out is None or not held_out.episodes:
        return chosen
    from orbitdata.load.select import select_episodes
    from orbitdata.load.tables import load_episode_table

    keep = select_episodes(load_episode_table(source, "train", {}), chosen, "train")
    out = set(held_out.episodes)
    return [int(e) for e in keep if int(e) not in out]


def split_selection(split: str, held_out: ValidationSplit) -> tuple[str, list[int] | None]:
    """(dataset split, episodes=) of an evaluation on ``split``: "test", or "val", the run's
    validation episodes of the train split."""
    if split not in EVAL_SPLITS:
        raise ValueError(f"split {split!r}: choose one of {', '.join(EVAL_SPLITS)}")
    if split == "test":
        return "test", None
    if not held_out.episodes:
        raise ValueError(
            "this run holds out no validation episodes; train it with --val-fraction (e.g. 0.1) to "
            "make choices on a validation split"
        )
    return "train", list(held_out.episodes)
