"""The depth head scored where the planner needs it: by band of true distance, the share of cells
it misses (puts at or beyond the planner's range, so they are no obstacle) and the share of far
cells it brings inside that range (phantom obstacles). ``orbitmodel eval rollout`` and
``orbitmodel depth`` both report these."""

from __future__ import annotations

import torch

from orbitmodel.plan.config import MAX_RANGE

DEPTH_BANDS_M = (2.0, 5.0, 10.0)  # metres: upper edges of the near bands of true depth


def depth_by_band(pred: torch.Tensor, true: torch.Tensor, edges=DEPTH_BANDS_M, seen_within: float = MAX_RANGE) -> dict:
    """pred, true (...) metres -> per band of true depth [0, e1), [e1, e2), ..., [e_last, inf):
    cells, MAE and ``missed`` (the share predicted at or beyond ``seen_within``, i.e. dropped by
    the planner); and ``phantom``, the share of cells truly at or beyond ``seen_within`` that are
    predicted inside it."""
    pred, true = pred.flatten().double(), true.flatten().double()
    bounds = (0.0, *edges, float("inf"))
    bands = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        inside = (true >= lo) & (true < hi)
        n = int(inside.sum())
        bands.append(
            {
                "from_m": lo,
                "to_m": None if hi == float("inf") else hi,
                "cells": n,
                "mae_m": float((pred[inside] - true[inside]).abs().mean()) if n else None,
                "missed": float((pred[inside] >= seen_within).double().mean()) if n else None,
            }
        )
    far = true >= seen_within
    phantom = float((pred[far] < seen_within).double().mean()) if far.any() else None
    return {"range_m": seen_within, "bands": bands, "phantom": phantom}


def band_label(band: dict) -> str:
    """'0-2 m', ..., '>= 10 m': a band of :func:`depth_by_band`."""
    return f"{band['from_m']:g}-{band['to_m']:g} m" if band["to_m"] is not None else f">= {band['from_m']:g} m"


def band_lines(bands: dict | None) -> list[str]:
    """One head's :func:`depth_by_band`, as ``eval rollout`` prints it."""
    if not bands:
        return []
    rows = [f"  depth by true distance (missed: predicted at or beyond the planner's {bands['range_m']:g} m):"]
    for b in bands["bands"]:
        if b["cells"]:
            rows.append(
                f"    {band_label(b):>9}: {b['cells']:8d} cells, MAE {b['mae_m']:.2f} m, missed {100 * b['missed']:.1f} %"
            )
    if bands["phantom"] is not None:
        rows.append(
            f"    far cells predicted inside {bands['range_m']:g} m (phantom obstacles): {100 * bands['phantom']:.1f} %"
        )
    return rows


def comparison_lines(result: dict) -> list[str]:
    """Two heads' bands side by side (``orbitmodel depth``: Stage I -> refit)."""
    rows = [
        f"depth head on {result['config']['test_frames']} {result['config'].get('eval_split', 'test')} frames: "
        "Stage I -> refit "
        f"(missed: predicted at or beyond {result['config']['near_m']:g} m)"
    ]
    before, after = result["stage1"], result["refit"]
    rows.append(f"  all cells: MAE {before['mae_m']:.2f} -> {after['mae_m']:.2f} m")
    for b, a in zip(before["bands"], after["bands"]):
        if b["cells"]:
            rows.append(
                f"  {band_label(b):>9} ({b['cells']} cells): MAE {b['mae_m']:.2f} -> {a['mae_m']:.2f} m, "
                f"missed {100 * b['missed']:.1f} -> {100 * a['missed']:.1f} %"
            )
    if before["phantom"] is not None:
        rows.append(
            f"  far cells predicted inside {result['config']['near_m']:g} m: "
            f"{100 * before['phantom']:.2f} -> {100 * after['phantom']:.2f} %"
        )
    return rows
