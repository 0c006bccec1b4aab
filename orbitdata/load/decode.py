"""Arrow rows of one episode -> a window of tensors. Images decode with OpenCV from the stored bytes.

Shared by the map-style and the streaming dataset, so both give identical windows. What a
column becomes follows from its Arrow type: an Image struct decodes (RGB to ``(T, 3, H, W)``
uint8, ``observation.depth`` to ``(T, H, W)`` float32 metres), a fixed-size list becomes
``(T, n)`` (``observation.depth_low``: ``(T, 16, 16)``), an integer ``(T,)`` int64, a float
``(T,)`` float32, a bool ``(T,)`` bool.

Windows decode straight into preallocated output (one window, or a whole batch: see
:meth:`WindowDecoder.allocate`), so a frame is written once, where the training step reads it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import cv2
import numpy as np
import pyarrow as pa
import torch

from orbitdata import schema as S
from orbitdata.codecs import MM_PER_M
from orbitdata.load.config import IS_PAD, WindowConfig
from orbitdata.load.memory import empty

# Per-frame shapes that the flat Arrow list does not carry.
FRAME_SHAPES = {S.DEPTH_LOW: (S.DEPTH_LOW_SIDE, S.DEPTH_LOW_SIDE)}

_configured_pid: int | None = None


def configure_process() -> None:
    """Once per process: keep OpenCV single-threaded inside DataLoader workers.

    OpenCV's thread pool does not survive ``fork`` reliably, and workers are the parallelism.
    """
    global _configured_pid
    if _configured_pid == os.getpid():
        return
    _configured_pid = os.getpid()
    if torch.utils.data.get_worker_info() is not None:
        cv2.setNumThreads(1)


def _split_writes_in_place() -> bool:
    """Whether this OpenCV build's ``cv2.split`` fills the planes it is given (checked once)."""
    img = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    out = np.zeros((3, 2, 3), np.uint8)
    cv2.split(img, [out[0], out[1], out[2]])
    return np.array_equal(out, img.transpose(2, 0, 1))


_SPLIT_IN_PLACE = _split_writes_in_place()


@dataclass(frozen=True)
class Column:
    name: str
    kind: str  # "rgb" | "depth" | "list" | "scalar"
    frame_shape: tuple[int, ...]  # per frame, for "list" (an image size is read from its first frame)
    dtype: torch.dtype


def _is_image(t: pa.DataType) -> bool:
    return pa.types.is_struct(t) and t.get_field_index("bytes") >= 0


def plan_columns(schema: pa.Schema, names: tuple[str, ...]) -> tuple[Column, ...]:
    """How to decode each named column of ``schema``; raises on a type the loader cannot batch."""
    plan = []
    for name in names:
        t = schema.field(name).type
        if _is_image(t):
            depth = name == S.DEPTH
            plan.append(Column(name, "depth" if depth else "rgb", (), torch.float32 if depth else torch.uint8))
        elif pa.types.is_fixed_size_list(t) and pa.types.is_floating(t.value_type):
            plan.append(Column(name, "list", FRAME_SHAPES.get(name, (t.list_size,)), torch.float32))
        elif pa.types.is_boolean(t):
            plan.append(Column(name, "scalar", (), torch.bool))
        elif pa.types.is_integer(t):
            plan.append(Column(name, "scalar", (), torch.int64))
        elif pa.types.is_floating(t):
            plan.append(Column(name, "scalar", (), torch.float32))
        elif S.is_privileged(name):
            raise ValueError(
                f"column {name!r} is privileged (for oracles and validation) and holds one pose per obstacle, "
                "which windows cannot stack; leave it out of columns= and read it from the data shards with pyarrow"
            )
        else:
            raise ValueError(
                f"column {name!r} has type {t}, which the window loader cannot stack; leave it out of columns="
            )
    return tuple(plan)


def _binary_views(col: pa.ChunkedArray) -> list[np.ndarray]:
    """The encoded bytes of every row, as zero-copy uint8 views."""
    out = []
    for chunk in col.chunks:
        data = chunk.field("bytes")
        if data.null_count:
            raise ValueError("missing image bytes")
        wide = pa.types.is_large_binary(data.type)
        _, offsets, values = data.buffers()
        dtype = np.dtype(np.int64 if wide else np.int32)
        offsets = np.frombuffer(offsets, dtype, count=len(data) + 1, offset=data.offset * dtype.itemsize)
        values = np.frombuffer(values, np.uint8) if values is not None else np.zeros(0, np.uint8)
        out += [values[offsets[i] : offsets[i + 1]] for i in range(len(data))]
    return out


def _fit(img: np.ndarray, hw: tuple[int, int], resize: bool, interpolation: int, i: int) -> np.ndarray:
    if img.shape[:2] == hw:
        return img
    if not resize:
        raise ValueError(
            f"frame {i} of the window is {img.shape[1]}x{img.shape[0]} px, not "
            f"{hw[1]}x{hw[0]} like the dataset's first frame; pass image_size= to resize every "
            "frame to one size"
        )
    return cv2.resize(img, (hw[1], hw[0]), interpolation=interpolation)


def decode_rgb_frames(blobs: list[np.ndarray], out: np.ndarray, resize: bool) -> None:
    """JPEG/PNG bytes -> ``out`` (T, 3, H, W) uint8 RGB; frames past ``len(blobs)`` repeat the last."""
    hw = out.shape[2:]
    for i, blob in enumerate(blobs):
        img = cv2.imdecode(blob, cv2.IMREAD_COLOR_RGB)  # (H, W, 3) uint8
        if img is None:
            raise ValueError(f"frame {i} of the window is not a decodable image")
        img = _fit(img, hw, resize, cv2.INTER_AREA, i)
        if _SPLIT_IN_PLACE:  # HWC -> CHW, much faster than a strided copy
            cv2.split(img, [out[i, 0], out[i, 1], out[i, 2]])
        else:
            out[i] = img.transpose(2, 0, 1)
    out[len(blobs) :] = out[len(blobs) - 1]


def decode_depth_frames(blobs: list[np.ndarray], out: np.ndarray, resize: bool) -> None:
    """16-bit PNG millimetres -> ``out`` (T, H, W) float32 metres (0 = no return)."""
    hw = out.shape[1:]
    for i, blob in enumerate(blobs):
        img = cv2.imdecode(blob, cv2.IMREAD_UNCHANGED)  # (H, W) uint16 mm
        if img is None or img.dtype != np.uint16 or img.ndim != 2:
            raise ValueError(f"frame {i} of the window is not a 16-bit single-channel PNG")
        # Nearest neighbour: averaging would invent depths between an object and "no return".
        img = _fit(img, hw, resize, cv2.INTER_NEAREST, i)
        np.divide(img, np.float32(MM_PER_M), out=out[i])
    out[len(blobs) :] = out[len(blobs) - 1]


def _place(rows: pa.Table) -> str:
    episode, first = rows.column(S.EPISODE_INDEX)[0].as_py(), rows.column(S.FRAME_INDEX)[0].as_py()
    return f"episode {episode}, window starting at frame {first}"


class WindowDecoder:
    """Turns the ``n_real <= T`` rows of a window into its tensors."""

    def __init__(self, schema: pa.Schema, names: tuple[str, ...], config: WindowConfig):
        self.columns = plan_columns(schema, names)
        self.config = config
        self._image_hw: dict[str, tuple[int, int]] = {}

    def _frame_shape(self, col: Column, rows: pa.Table) -> tuple[int, ...]:
        if col.kind not in ("rgb", "depth"):
            return col.frame_shape
        if col.name not in self._image_hw:
            size = self.config.image_size
            if size is not None:
                self._image_hw[col.name] = (size, size)
            else:  # the stored size, from the first frame (a dataset has one image size)
                img = cv2.imdecode(_binary_views(rows.column(col.name).slice(0, 1))[0], cv2.IMREAD_UNCHANGED)
                if img is None:
                    raise ValueError(
                        f"{_place(rows)}, column {col.name!r}: frame 0 of the window is not a decodable "
                        "image; the dataset is corrupt (run `orbitdata validate`)"
                    )
                self._image_hw[col.name] = img.shape[:2]
        hw = self._image_hw[col.name]
        return (3, *hw) if col.kind == "rgb" else hw

    def allocate(self, rows: pa.Table, batch: int | None = None) -> dict[str, torch.Tensor]:
        """Uninitialised output for one window (``batch=None``) or ``batch`` windows, like ``rows``."""
        shared = batch is not None and torch.utils.data.get_worker_info() is not None

        def lead(col: str | None = None) -> tuple[int, ...]:
            T = self.config.context if col in self.config.context_only else self.config.length
            return (T,) if batch is None else (batch, T)

        out = {c.name: empty((*lead(c.name), *self._frame_shape(c, rows)), c.dtype, shared) for c in self.columns}
        out[IS_PAD] = empty(lead(), torch.bool, shared)
        return out

    def __call__(self, rows: pa.Table) -> dict[str, torch.Tensor]:
        """The window of these rows, in new tensors."""
        out = self.allocate(rows)
        self.decode_into(rows, out)
        return out

    def decode_into(self, rows: pa.Table, out: dict[str, torch.Tensor]) -> None:
        """Fill ``out`` (one window's tensors, e.g. ``batch[k][j]``) from the window's real rows."""
        T, n = self.config.length, rows.num_rows
        assert 0 < n <= T, f"a window holds 1..{T} real rows, got {n}"
        for col in self.columns:
            try:
                values = rows.column(col.name)
                if col.name in self.config.context_only:  # the context is real (pad only runs past the end)
                    values = values.slice(0, self.config.context)
                self._column(col, values, out[col.name].numpy())
            except ValueError as err:
                raise ValueError(
                    f"{_place(rows)}, column {col.name!r}: {err}; "
                    "the dataset is corrupt (run `orbitdata validate`), or pass columns= without it"
                ) from None
        is_pad = out[IS_PAD].numpy()  # (T,) bool
        is_pad[:n] = False
        is_pad[n:] = True

    def _column(self, col: Column, values: pa.ChunkedArray, out: np.ndarray) -> None:
        resize = self.config.image_size is not None
        if col.kind == "rgb":
            return decode_rgb_frames(_binary_views(values), out, resize)
        if col.kind == "depth":
            return decode_depth_frames(_binary_views(values), out, resize)
        if values.null_count:
            raise ValueError("null values")
        n = len(values)
        if col.kind == "list":
            for chunk, at in zip(values.chunks, np.cumsum([0] + [len(c) for c in values.chunks])):
                out[at : at + len(chunk)] = chunk.flatten().to_numpy().reshape(len(chunk), *col.frame_shape)
        else:
            out[:n] = values.to_numpy()
        out[n:] = out[n - 1]
