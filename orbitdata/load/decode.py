"""Arrow rows of one episode -> a window of tensors. Images decode with OpenCV from the stored bytes.

Shared by the map-style and the streaming dataset, so both give identical windows. What a
column becomes follows from its Arrow type: an Image struct decodes (RGB to ``(T, 3, H, W)``
uint8, ``observation.depth`` to ``(T, H, W)`` float32 metres), a fixed-size list becomes
``(T, n)`` (``observation.depth_low``: ``(T, 16, 16)``), a scalar ``(T,)``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import cv2
import numpy as np
import pyarrow as pa
import torch

from orbitdata import schema as S
from orbitdata.dataset.encode import MM_PER_M
from orbitdata.load.config import IS_PAD, WindowConfig

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


@dataclass(frozen=True)
class Column:
    name: str
    kind: str  # "rgb" | "depth" | "list" | "scalar"
    frame_shape: tuple[int, ...]  # for "list" only
    dtype: torch.dtype | None  # for "list" / "scalar"


def _is_image(t: pa.DataType) -> bool:
    return pa.types.is_struct(t) and t.get_field_index("bytes") >= 0


def plan_columns(schema: pa.Schema, names: tuple[str, ...]) -> tuple[Column, ...]:
    """How to decode each named column of ``schema``; raises on a type the loader cannot batch."""
    plan = []
    for name in names:
        t = schema.field(name).type
        if _is_image(t):
            plan.append(Column(name, "depth" if name == S.DEPTH else "rgb", (), None))
        elif pa.types.is_fixed_size_list(t) and pa.types.is_floating(t.value_type):
            plan.append(Column(name, "list", FRAME_SHAPES.get(name, (t.list_size,)), torch.float32))
        elif pa.types.is_boolean(t):
            plan.append(Column(name, "scalar", (), torch.bool))
        elif pa.types.is_integer(t):
            plan.append(Column(name, "scalar", (), torch.int64))
        elif pa.types.is_floating(t):
            plan.append(Column(name, "scalar", (), torch.float32))
        else:
            raise ValueError(f"column {name!r} has type {t}, which the window loader cannot stack; leave it out of columns=")
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
        offsets = np.frombuffer(offsets, np.int64 if wide else np.int32, count=len(data) + 1, offset=data.offset * (8 if wide else 4))
        values = np.frombuffer(values, np.uint8) if values is not None else np.zeros(0, np.uint8)
        out += [values[offsets[i]:offsets[i + 1]] for i in range(len(data))]
    return out


def _split_writes_in_place() -> bool:
    """Whether this OpenCV build's ``cv2.split`` fills the planes it is given (checked once)."""
    img = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    out = np.zeros((3, 2, 3), np.uint8)
    cv2.split(img, [out[0], out[1], out[2]])
    return np.array_equal(out, img.transpose(2, 0, 1))


_SPLIT_IN_PLACE = _split_writes_in_place()


def decode_rgb_frames(blobs: list[np.ndarray], length: int, size: int | None) -> np.ndarray:
    """JPEG/PNG bytes -> ``(length, 3, H, W)`` uint8 RGB; frames past ``len(blobs)`` repeat the last."""
    out = None
    for i, blob in enumerate(blobs):
        img = cv2.imdecode(blob, cv2.IMREAD_COLOR_RGB)  # (H, W, 3) uint8
        if img is None:
            raise ValueError(f"frame {i} of the window is not a decodable image")
        if size is not None and img.shape[:2] != (size, size):
            img = cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA)
        if out is None:
            out = np.empty((length, 3, *img.shape[:2]), np.uint8)
        if _SPLIT_IN_PLACE:  # HWC -> CHW ~10x faster than a strided copy
            cv2.split(img, [out[i, 0], out[i, 1], out[i, 2]])
        else:
            out[i] = img.transpose(2, 0, 1)
    out[len(blobs):] = out[len(blobs) - 1]
    return out


def decode_depth_frames(blobs: list[np.ndarray], length: int, size: int | None) -> np.ndarray:
    """16-bit PNG millimetres -> ``(length, H, W)`` float32 metres (0 = no return)."""
    out = None
    for i, blob in enumerate(blobs):
        img = cv2.imdecode(blob, cv2.IMREAD_UNCHANGED)  # (H, W) uint16 mm
        if img is None or img.dtype != np.uint16 or img.ndim != 2:
            raise ValueError(f"frame {i} of the window is not a 16-bit single-channel PNG")
        if size is not None and img.shape != (size, size):
            img = cv2.resize(img, (size, size), interpolation=cv2.INTER_NEAREST)
        if out is None:
            out = np.empty((length, *img.shape), np.float32)
        np.divide(img, np.float32(MM_PER_M), out=out[i])
    out[len(blobs):] = out[len(blobs) - 1]
    return out


def _pad(values: np.ndarray, length: int) -> np.ndarray:
    n = len(values)
    if n == length:
        return values
    return np.concatenate([values, np.repeat(values[n - 1:n], length - n, axis=0)])


class WindowDecoder:
    """Turns the ``n_real <= T`` rows of a window into its dict of tensors."""

    def __init__(self, schema: pa.Schema, names: tuple[str, ...], config: WindowConfig):
        self.columns = plan_columns(schema, names)
        self.config = config

    def __call__(self, rows: pa.Table) -> dict[str, torch.Tensor]:
        T, n = self.config.length, rows.num_rows
        assert 0 < n <= T, f"a window holds 1..{T} real rows, got {n}"
        item: dict[str, torch.Tensor] = {}
        for col in self.columns:
            try:
                item[col.name] = self._column(col, rows.column(col.name), T)
            except ValueError as err:
                ep = rows.column(S.EPISODE_INDEX)[0].as_py()
                first = rows.column(S.FRAME_INDEX)[0].as_py()
                raise ValueError(
                    f"episode {ep}, window starting at frame {first}, column {col.name!r}: {err}; "
                    "the dataset is corrupt (run `orbitdata validate`)"
                ) from None
        is_pad = np.zeros(T, bool)  # (T,)
        is_pad[n:] = True
        item[IS_PAD] = torch.from_numpy(is_pad)
        return item

    def _column(self, col: Column, values: pa.ChunkedArray, T: int) -> torch.Tensor:
        size = self.config.image_size
        if col.kind == "rgb":
            return torch.from_numpy(decode_rgb_frames(_binary_views(values), T, size))  # (T, 3, H, W) uint8
        if col.kind == "depth":
            return torch.from_numpy(decode_depth_frames(_binary_views(values), T, size))  # (T, H, W) metres
        if values.null_count:
            raise ValueError("null values")
        if col.kind == "list":
            flat = np.concatenate([c.flatten().to_numpy() for c in values.chunks])
            array = flat.reshape(len(values), *col.frame_shape)  # (n, *frame_shape)
        else:
            array = values.to_numpy()  # (n,)
        array = np.require(_pad(array, T), requirements=["C", "W"])  # a read-only memory map view is copied
        return torch.from_numpy(array).to(col.dtype)
