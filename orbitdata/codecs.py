"""The on-disk codec contract: how frames become bytes, and how meta/stats.json samples the data.

Deterministic: the same pixels always give the same bytes. RGB: JPEG through OpenCV's
libjpeg-turbo. Depth: 16-bit grayscale PNG of millimetres, 0 = no return, written with the PNG
"up" filter. Both decode with Pillow (what ``datasets`` uses) and OpenCV (what the loader uses).
The writer, the loader, the validator and the figures all take these numbers from here.
"""

from __future__ import annotations

import cv2
import numpy as np

from orbitdata import schema as S

MM_PER_M = 1000.0  # depth PNG unit: millimetres
DEPTH_MAX_MM = 65535

# The "up" filter suits depth (smooth surfaces, large empty areas): at 224 px it is
# faster than OpenCV's default adaptive filtering and gives smaller files. The name is what
# meta/info.json records; the encoder takes OpenCV's flag for it from this table.
PNG_FILTER = "up"
_CV2_PNG_FILTERS = {"up": cv2.IMWRITE_PNG_FILTER_UP}

# ---- the stats recipe (meta/stats.json; the validator recomputes it) ------------------------
# mean / std / min / max are exact over every train row; q01 / q99 come from every stride-th row,
# the stride chosen so that at most QUANTILE_ROWS rows are kept. RGB channel statistics (values
# in [0, 1]) come from every IMAGE_STRIDE-th train frame, their quantiles from at most
# QUANTILE_ROWS pixels in all, on a walk of PIXEL_STRIDE through each of those frames.
QUANTILE_ROWS = 20_000
IMAGE_STRIDE = 50
PIXEL_STRIDE = 97  # prime: coprime with every image size
QUANTILES = (("q01", 0.01), ("q99", 0.99))
VECTOR_FEATURES = (S.STATE, S.ACTION, S.DEPTH_LOW)
SCALAR_FEATURES = (S.MIN_CLEARANCE, S.TIMESTAMP)
IMAGE_CHANNELS = 3


def stats_width(name: str) -> int:
    """Values per row of a feature in meta/stats.json: the fixed list size, 3 for RGB, else 1."""
    if name == S.IMAGE:
        return IMAGE_CHANNELS
    return S.column_width(name)


def encode_rgb(rgb: np.ndarray, quality: int) -> bytes:
    """(H, W, 3) uint8 RGB -> JPEG bytes (4:2:0)."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV failed to encode a JPEG frame")
    return buf.tobytes()


def depth_to_mm(depth: np.ndarray) -> np.ndarray:
    """Metres (0 = no return) -> uint16 millimetres, rounded."""
    return np.clip(np.rint(depth * MM_PER_M), 0, DEPTH_MAX_MM).astype(np.uint16)


def encode_depth(depth: np.ndarray, compression: int) -> bytes:
    """(H, W) float32 metres -> 16-bit PNG bytes of millimetres at zlib level ``compression``."""
    params = [cv2.IMWRITE_PNG_COMPRESSION, int(compression), cv2.IMWRITE_PNG_FILTER, _CV2_PNG_FILTERS[PNG_FILTER]]
    ok, buf = cv2.imencode(".png", depth_to_mm(depth), params)
    if not ok:
        raise RuntimeError("OpenCV failed to encode a depth PNG")
    return buf.tobytes()


def decode_rgb(data: bytes) -> np.ndarray:
    """JPEG (or PNG) bytes -> (H, W, 3) uint8 RGB."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError("undecodable RGB frame")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def decode_depth(data: bytes) -> np.ndarray:
    """16-bit PNG bytes -> (H, W) float32 metres (0 = no return)."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        raise ValueError("undecodable depth frame (expected a 16-bit single-channel PNG)")
    return img.astype(np.float32) / MM_PER_M
