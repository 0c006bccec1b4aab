"""``WindowConfig``: what a window is (length, stride, padding, columns, image size)."""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from orbitdata import schema as S

# Always in an item: they say where the window comes from, and the index is built from them.
KEY_COLUMNS = (S.EPISODE_INDEX, S.FRAME_INDEX)
IS_PAD = "is_pad"  # not a dataset column: the loader's mask of padded frames


@dataclass(frozen=True)
class WindowConfig:
    """A window is ``context + horizon`` consecutive frames of one episode.

    Args:
        context: frames the model observes (m in the paper).
        horizon: frames that follow, whose actions and targets the model predicts (n).
        stride: frames between the starts of two consecutive windows of an episode.
        pad: ``False``: every frame of a window is real, so an episode of length L gives
            windows starting at 0..L-T. ``True``: the context must be real but the horizon may
            run past the episode end; those frames repeat the last frame and ``is_pad`` marks
            them, so windows start at 0..L-context.
        image_size: resize images (and full-resolution depth) to this square size in pixels;
            ``None`` keeps the stored size. RGB uses area averaging, depth nearest neighbour
            (averaging would invent depths between an object and "no return").
        columns: the dataset columns to load; ``None`` = every step column but the privileged
            ones (``privileged.*``: the dynamic tier's obstacle poses, for oracles and validation,
            never a learned pilot's input). ``episode_index`` and ``frame_index`` are always
            included. Leaving out ``observation.depth`` skips the costliest decode.
        context_only: columns read for the ``context`` frames only (their tensors are
            ``(context, ...)``): e.g. the image, for a policy that observes the first frames and
            predicts only actions over the rest. The horizon's frames are never decoded.
    """

    context: int = 8
    horizon: int = 12
    stride: int = 1
    pad: bool = False
    image_size: int | None = None
    columns: tuple[str, ...] | None = None
    context_only: tuple[str, ...] = ()

    def __post_init__(self):
        for name in ("context", "horizon", "stride", "image_size"):
            value = getattr(self, name)
            if not (value is None and name == "image_size") and (
                isinstance(value, bool) or not isinstance(value, numbers.Integral)
            ):
                raise ValueError(f"{name}={value!r}: give a whole number")
        if not isinstance(self.pad, (bool, np.bool_)):
            raise ValueError(f"pad={self.pad!r}: give True or False")
        if self.context < 1:
            raise ValueError(f"context={self.context}: a window needs at least one context frame")
        if self.horizon < 0:
            raise ValueError(f"horizon={self.horizon}: the horizon cannot be negative (0 = context only)")
        if self.stride < 1:
            raise ValueError(f"stride={self.stride}: use a stride of 1 or more frames")
        if self.image_size is not None and self.image_size < 1:
            raise ValueError(f"image_size={self.image_size}: give a positive size in pixels, or None")
        if self.columns is not None:
            if isinstance(self.columns, str):
                raise ValueError(f"columns={self.columns!r}: pass a list of column names, not one string")
            object.__setattr__(self, "columns", tuple(self.columns))
        if isinstance(self.context_only, str):
            raise ValueError(f"context_only={self.context_only!r}: pass a list of column names, not one string")
        object.__setattr__(self, "context_only", tuple(self.context_only))
        if set(self.context_only) & set(KEY_COLUMNS):
            raise ValueError(
                f"context_only={list(self.context_only)}: {', '.join(KEY_COLUMNS)} are read for every frame"
            )
        if self.columns is not None and set(self.context_only) - set(self.columns):
            raise ValueError(
                f"context_only={list(self.context_only)} names columns not in columns={list(self.columns)}"
            )

    @property
    def length(self) -> int:
        """T: frames per window."""
        return self.context + self.horizon

    @property
    def min_frames(self) -> int:
        """The shortest episode that yields a window."""
        return self.context if self.pad else self.length

    def wanted(self, available: tuple[str, ...] | list[str]) -> tuple[str, ...]:
        """The columns to read, in the dataset's order; raises if one is missing."""
        available = tuple(available)
        for name in KEY_COLUMNS:
            if name not in available:
                raise ValueError(
                    f"the steps table has no {name!r} column (it has {list(available)}); "
                    "windows are cut by episode_index/frame_index, so this is not an orbitdata steps table"
                )
        asked = dict.fromkeys((self.columns or ()) + self.context_only)  # context_only is within columns when given
        missing = [c for c in asked if c not in available]
        if missing:
            raise ValueError(f"column(s) {missing} not in the dataset; available: {list(available)}")
        if self.columns is None:
            return tuple(c for c in available if not S.is_privileged(c))
        wanted = set(self.columns) | set(KEY_COLUMNS)
        return tuple(c for c in available if c in wanted)
