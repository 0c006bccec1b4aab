"""Table I's errors: per-step absolute errors per quantity, and their summary over windows.

Per window, the error of a quantity at a frame is the mean absolute error over its components
(the attitude: the geodesic angle between the true and predicted rotations); a cell of the table
is, over the windows, the mean (and std) of the per-window average over frames 1..h (the paper's
MAE at h) and of the error at frame h itself (``at_h``).
"""

from __future__ import annotations

import torch

from orbitmodel.kinematics import FUEL, ROT, P, V, W, geodesic_angle, rot6d_to_matrix

QUANTITIES = {"position": "m", "velocity": "m/s", "rotation": "rad", "angular_velocity": "rad/s", "fuel": "ratio"}
# Table I of the paper (MAE at h = 25 and h = 50 steps of 0.04 s).
PAPER = {
    25: {"position": 0.0394, "velocity": 0.0636, "rotation": 0.0676, "angular_velocity": 0.0883, "fuel": 0.0019},
    50: {"position": 0.0813, "velocity": 0.1191, "rotation": 0.2034, "angular_velocity": 0.1557, "fuel": 0.0033},
}


def step_errors(pred: torch.Tensor, true: torch.Tensor) -> dict[str, torch.Tensor]:
    """Per-step absolute errors (K, n) of states (K, n, 16), per quantity."""
    d = (pred - true).abs()
    return {
        "position": d[..., P].mean(-1),
        "velocity": d[..., V].mean(-1),
        "rotation": geodesic_angle(rot6d_to_matrix(true[..., ROT]), rot6d_to_matrix(pred[..., ROT])),
        "angular_velocity": d[..., W].mean(-1),
        "fuel": d[..., FUEL].mean(-1),
    }


def summarise(errors: dict[str, dict[str, torch.Tensor]], horizons) -> dict:
    """row -> quantity -> {"h25": {"mean", "std", "at_h", "at_h_std"}, ..., "per_step": [...]} from
    (K, n) errors: mean and std over windows of the MAE over frames 1..h, and of the error at h."""
    table = {}
    for row, per_q in errors.items():
        table[row] = {}
        for q, e in per_q.items():
            entry = {}
            for h in horizons:
                over, at = e[:, :h].mean(1), e[:, h - 1]  # (K,) each
                entry[f"h{h}"] = {
                    "mean": float(over.mean()),
                    "std": float(over.std(unbiased=False)),
                    "at_h": float(at.mean()),
                    "at_h_std": float(at.std(unbiased=False)),
                }
            entry["per_step"] = [float(x) for x in e.mean(0)]
            table[row][q] = entry
    return table
