"""Per-feature statistics of the train split (``meta/stats.json``), computed in one pass.

The recipe (which rows, frames and pixels) is part of the contract: its numbers are in
:mod:`orbitdata.codecs`. mean / std / min / max are exact over every row, accumulated in
float64 in episode order. q01 / q99 come from a deterministic sample: every ``stride``-th row,
with the stride chosen so that at most ``QUANTILE_ROWS`` rows are kept. Image channel
statistics (RGB in [0, 1]) come from every ``IMAGE_STRIDE``-th frame (moments over all its
pixels); their quantiles from at most ``QUANTILE_ROWS`` pixels in all, spread over those frames
and over the image, so memory stays flat in the dataset size. ``count`` says how many values
each used, ``q_count`` how many the quantiles used.
"""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from orbitdata import schema as S
from orbitdata.codecs import (
    IMAGE_CHANNELS,
    IMAGE_STRIDE,
    PIXEL_STRIDE,
    QUANTILE_ROWS,
    QUANTILES,
    SCALAR_FEATURES,
    VECTOR_FEATURES,
    decode_rgb,
    stats_width,
)


def _matrix(column: pa.ChunkedArray | pa.Array, width: int) -> np.ndarray:
    if isinstance(column, pa.ChunkedArray):
        column = column.combine_chunks()
    if width == 1:
        return column.to_numpy(zero_copy_only=False).astype(np.float64).reshape(-1, 1)
    return column.flatten().to_numpy(zero_copy_only=False).astype(np.float64).reshape(-1, width)


class _Moments:
    def __init__(self, width: int):
        self.n = 0
        self.sum = np.zeros(width)
        self.sumsq = np.zeros(width)
        self.min = np.full(width, np.inf)
        self.max = np.full(width, -np.inf)
        self.sample: list[np.ndarray] = []

    def update(self, x: np.ndarray, sample_rows: np.ndarray | None) -> None:
        if len(x) == 0:
            return
        self.n += len(x)
        self.sum += x.sum(axis=0)
        self.sumsq += (x * x).sum(axis=0)
        self.min = np.minimum(self.min, x.min(axis=0))
        self.max = np.maximum(self.max, x.max(axis=0))
        if sample_rows is not None and len(sample_rows):
            self.sample.append(x[sample_rows])

    def result(self) -> dict:
        mean = self.sum / max(self.n, 1)
        var = np.maximum(self.sumsq / max(self.n, 1) - mean * mean, 0.0)
        out = {"count": int(self.n), "mean": mean, "std": np.sqrt(var), "min": self.min, "max": self.max}
        if self.sample:
            sample = np.concatenate(self.sample)
            for key, p in QUANTILES:
                out[key] = np.quantile(sample, p, axis=0)
            out["q_count"] = int(len(sample))  # size of the sample the quantiles come from
        return {k: (v if isinstance(v, int) else [float(f"{x:.7g}") for x in np.atleast_1d(v)]) for k, v in out.items()}


class StatsAccumulator:
    """Feed steps tables of one split in episode order; ``result()`` gives the stats dict."""

    def __init__(self, total_rows: int):
        self.stride = max(1, math.ceil(total_rows / QUANTILE_ROWS))
        self.rows_seen = 0
        self.widths = {name: stats_width(name) for name in VECTOR_FEATURES + SCALAR_FEATURES}
        self.moments = {name: _Moments(width) for name, width in self.widths.items()}
        self.image = _Moments(IMAGE_CHANNELS)
        n_images = max(1, math.ceil(total_rows / IMAGE_STRIDE))
        self.pixels_per_image = max(1, QUANTILE_ROWS // n_images)
        self.images_seen = 0

    def update(self, table: pa.Table) -> None:
        n = table.num_rows
        global_rows = np.arange(self.rows_seen, self.rows_seen + n)
        sample_rows = np.flatnonzero(global_rows % self.stride == 0)
        image_rows = np.flatnonzero(global_rows % IMAGE_STRIDE == 0)
        self.rows_seen += n
        for name, acc in self.moments.items():
            acc.update(_matrix(table.column(name), self.widths[name]), sample_rows)
        if len(image_rows):
            blobs = table.column(S.IMAGE).combine_chunks().field("bytes")
            for i in image_rows:
                pixels = decode_rgb(blobs[int(i)].as_py()).reshape(-1, 3).astype(np.float64) / 255.0
                # A walk of prime stride through the image (no more often than every 97th pixel:
                # neighbours are correlated), starting elsewhere in each image.
                n_pix = len(pixels)
                keep = max(1, min(self.pixels_per_image, n_pix // PIXEL_STRIDE))
                start = (self.images_seen * 7919) % n_pix
                self.image.update(pixels, (start + PIXEL_STRIDE * np.arange(keep)) % n_pix)
                self.images_seen += 1

    def result(self) -> dict:
        out = {name: acc.result() for name, acc in self.moments.items()}
        if self.image.n:
            out[S.IMAGE] = self.image.result()
        return out
