"""Images: every RGB JPEG and depth PNG decodes, has the recorded size, and depth is plausible.

Speed (it sets the pace of a full validation): a JPEG is decoded at 1/8 scale, which still
entropy-decodes the whole stream (so it fails on the same truncation and corruption as a full
decode, at a fraction of its time) while its true size and channel count come from the
JPEG header. Frames kept for the statistics, and RGB images that are not JPEG, are decoded in full.
Depth PNGs are decoded in full (their values are checked), ``DEPTH_BATCH`` at a time (bounded
memory), and pooled with exact integer block sums.

Tolerances:

* depth values are millimetres, so a non-zero value may sit up to 1 mm outside the camera's
  [near, far] (the PNG stores ``rint(metres * 1000)``);
* ``DEPTH_LOW_TOL_M = 1 mm``: depth_low is pooled from float32 metres before the PNG rounds
  them to millimetres, so the pooled PNG differs from it by at most 0.5 mm (measured: 0.50 mm).

The dynamic tier's depth camera drops pixels (0, no return) after depth_low is pooled from the
scene's depth, so a dropped pixel of a cell may have been anything in [near, far]: a cell with
no empty pixel is checked exactly, one with k empty pixels against the range that k pixels
between near and far allow.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.codecs import MM_PER_M
from orbitdata.validate import checks as C
from orbitdata.validate.frames import Frames
from orbitdata.validate.report import Sink

DEPTH_MM_SLACK = 1.0
DEPTH_LOW_TOL_M = 1e-3
DEPTH_BATCH = 64  # depth images checked together: vectorised, ~6 MB at 224 px


@dataclass(frozen=True)
class Camera:
    """What meta/info.json says the images are."""

    height: int
    width: int
    near: float  # metres
    far: float  # metres; no-return pixels (0) count as this in depth_low

    @classmethod
    def from_info(cls, info: dict | None) -> "Camera | None":
        try:
            rgb = info["features"][S.IMAGE]["shape"]
            near, far = info["features"][S.DEPTH]["range_m"]
            return cls(int(rgb[0]), int(rgb[1]), float(near), float(far))
        except (KeyError, TypeError, ValueError, IndexError):
            return None


def jpeg_header(data: bytes) -> tuple[int, int, int] | None:
    """(height, width, channels) from a JPEG's start-of-frame marker; None if it is not a JPEG."""
    if data[:2] != b"\xff\xd8":
        return None
    i, n = 2, len(data)
    while i + 9 < n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        length = int.from_bytes(data[i + 2 : i + 4], "big")
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):  # SOFn (not DHT, JPG, DAC)
            return (int.from_bytes(data[i + 5 : i + 7], "big"), int.from_bytes(data[i + 7 : i + 9], "big"), data[i + 9])
        i += 2 + length
    return None


def _blobs(table: pa.Table, name: str) -> tuple[pa.Array, np.ndarray]:
    col = table.column(name).combine_chunks()
    valid = np.asarray(col.is_valid()) if col.null_count else np.ones(len(col), bool)
    data = col.field("bytes")
    if data.null_count:
        valid &= np.asarray(data.is_valid())
    return data, valid


def check_images(
    table: pa.Table,
    fr: Frames,
    depth_low: np.ndarray,
    camera: Camera | None,
    rel: str,
    sink: Sink,
    keep_rgb: np.ndarray,
    dropout: bool = False,
) -> dict[int, np.ndarray]:
    """Decode every frame of a row group. Returns the RGB pixels of the rows in ``keep_rgb``.
    ``dropout``: the depth images have dropped pixels that depth_low does not (the dynamic tier)."""
    rgb_blobs, rgb_ok = _blobs(table, S.IMAGE)
    depth_blobs, depth_ok = _blobs(table, S.DEPTH)
    keep = set(int(i) for i in keep_rgb)
    kept: dict[int, np.ndarray] = {}
    good_rows, good_depth = [], []  # depth images of the expected shape, checked together below
    ep, frame = fr.episode, fr.frame
    for i in range(table.num_rows):
        where = (rel, int(ep[i]), int(frame[i]))
        shape, rgb = None, None
        if rgb_ok[i]:
            buffer = rgb_blobs[i].as_buffer()
            header = jpeg_header(buffer[:4096].to_pybytes())
            full = header is None or i in keep
            decoded = cv2.imdecode(
                np.frombuffer(buffer, np.uint8), cv2.IMREAD_UNCHANGED if full else cv2.IMREAD_REDUCED_COLOR_8
            )
            if decoded is not None:
                shape = decoded.shape if header is None else header
                rgb = decoded if full else None
        if shape is None:
            sink.add(C.DECODE, f"{S.IMAGE} does not decode (missing or corrupt JPEG bytes)", *where)
        elif camera is not None and tuple(shape) != (camera.height, camera.width, 3):
            sink.add(
                C.SIZE,
                f"{S.IMAGE} is {'x'.join(map(str, shape))}, meta/info.json says {camera.height}x{camera.width}x3",
                *where,
            )
        elif i in keep and rgb is not None and rgb.ndim == 3:
            kept[i] = cv2.cvtColor(rgb, cv2.COLOR_BGR2RGB)
        depth = None
        if depth_ok[i]:
            depth = cv2.imdecode(np.frombuffer(depth_blobs[i].as_buffer(), np.uint8), cv2.IMREAD_UNCHANGED)
        if depth is None:
            sink.add(C.DECODE, f"{S.DEPTH} does not decode (missing or corrupt PNG bytes)", *where)
        elif depth.dtype != np.uint16 or depth.ndim != 2:
            shape = "x".join(map(str, depth.shape))
            sink.add(
                C.SIZE, f"{S.DEPTH} is a {shape} {depth.dtype} image, expected a single-channel 16-bit PNG", *where
            )
        elif camera is not None and depth.shape != (camera.height, camera.width):
            sink.add(
                C.SIZE,
                f"{S.DEPTH} is {depth.shape[0]}x{depth.shape[1]}, meta/info.json says {camera.height}x{camera.width}",
                *where,
            )
        elif camera is not None:
            good_rows.append(i)
            good_depth.append(depth)
        if len(good_rows) == DEPTH_BATCH or (good_rows and i == table.num_rows - 1):
            _check_depth(np.stack(good_depth), np.asarray(good_rows), fr, depth_low, camera, rel, sink, dropout)
            good_rows, good_depth = [], []
    return kept


def _check_depth(
    depth_mm: np.ndarray,
    rows: np.ndarray,
    fr: Frames,
    depth_low: np.ndarray,
    camera: Camera,
    rel: str,
    sink: Sink,
    dropout: bool = False,
) -> None:
    """depth_mm (K, H, W) uint16 of table rows ``rows``: range, then depth_low against the pooled image
    (``dropout``: each empty pixel anywhere in [near, far])."""
    ep, frame = fr.episode[rows], fr.frame[rows]
    lo, hi = camera.near * MM_PER_M - DEPTH_MM_SLACK, camera.far * MM_PER_M + DEPTH_MM_SLACK
    lowest = (depth_mm - np.uint16(1)).min(axis=(1, 2)).astype(np.int64) + 1  # 0 wraps to 65535: skips no-return
    highest = depth_mm.max(axis=(1, 2))
    out = (highest > 0) & ((lowest < lo) | (highest > hi))
    sink.add_rows(
        C.DEPTH_RANGE,
        np.flatnonzero(out),
        lambda k: (
            f"depth spans {lowest[k] / MM_PER_M:.3f}-"
            f"{highest[k] / MM_PER_M:.3f} m, outside the camera range [{camera.near:g}, {camera.far:g}] m"
        ),
        rel,
        ep,
        frame,
    )
    side = S.DEPTH_LOW_SIDE
    k, h, w = depth_mm.shape
    if h % side or w % side:
        return
    bh, bw = h // side, w // side
    # Exact block means in integers: sum rows of each block band, then columns of each block.
    sums = depth_mm.reshape(k * side, bh, w).sum(axis=1, dtype=np.uint32).reshape(k * side, side, bw).sum(axis=2)
    empty = (depth_mm == 0).reshape(k * side, bh, w).sum(axis=1, dtype=np.uint32)
    empty = empty.reshape(k * side, side, bw).sum(axis=2)
    far_mm = round(camera.far * MM_PER_M)  # no return counts as the far plane, as in the generator
    pooled = ((sums + empty * far_mm) / (bh * bw * MM_PER_M)).reshape(k, side * side)  # metres
    low = depth_low[rows]
    lowest_pooled = pooled
    if dropout:
        lowest_pooled = ((sums + empty * (camera.near * MM_PER_M)) / (bh * bw * MM_PER_M)).reshape(k, side * side)
    with np.errstate(invalid="ignore"):
        err = np.maximum(lowest_pooled - low, low - pooled) if dropout else np.abs(pooled - low)
        # out-of-range depth is already reported; non-finite depth_low is values.finite's
        bad = np.flatnonzero(~out & np.isfinite(low).all(axis=1) & (err.max(axis=1) > DEPTH_LOW_TOL_M))
    cell = err.argmax(axis=1) if len(bad) else None
    sink.add_rows(
        C.DEPTH_LOW,
        bad,
        lambda j: (
            f"depth_low cell {cell[j]} is {low[j, cell[j]]:.4f} m, the pooled depth image says "
            + (
                f"{pooled[j, cell[j]]:.4f} m"
                if lowest_pooled[j, cell[j]] == pooled[j, cell[j]]
                else f"{lowest_pooled[j, cell[j]]:.4f}-{pooled[j, cell[j]]:.4f} m (its empty pixels may be dropped)"
            )
            + f" (tolerance {DEPTH_LOW_TOL_M * 1000:g} mm)"
        ),
        rel,
        ep,
        frame,
    )
