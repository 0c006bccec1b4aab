"""How well does a body fitted to the pilot's history predict the body's turn, and from how much history?

    python benchmarks/check_fitted_body.py RUN DATASET [--frames 10 20 40 80] [--ridge 1e-5 1e-3] [--inferred] [--json OUT]

On the run's validation episodes (the train-split episodes it held out), at every 10th frame t
where the body turns at most 3 rad/s, :class:`~orbitmodel.plan.fitted_body.FittedBodyDynamics`
is shown the frames before t (at most ``frames`` of them, the actions between them) and rolls
the recorded thrusts out for 25 frames; its body rate and velocity there are set against the
recorded ones (mean absolute error over the 3 axes), split by whether the episode has a faulty
thruster. References: the design's body (no history: the fit's prior) and the body rate held
constant. ``--inferred`` scores the fit under RUN/body's learned prior at each ``--frames`` up to the
history it was trained on too (``orbitmodel body``; ``--set body=inferred``). Prints figures; asserts nothing. The flights with the fit are ``--set body=fitted``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from orbitdata.sim.config import SimConfig
from orbitmodel.kinematics import V, W
from orbitmodel.plan.fitted_body import FittedBodyDynamics
from orbitmodel.plan.inferred_body import InferredBodyDynamics, flown_episodes, load_inference
from orbitmodel.runs import read_run_config

AHEAD, EVERY, MAX_RATE = 25, 10, 3.0


def scores(dynamics: FittedBodyDynamics, flown, frames: int) -> dict:
    """{"fault" / "none": [body-rate error, velocity error, holding-rate error] means, and the window count}."""
    errors: dict[str, list] = {"fault": [], "none": []}
    for states, actions, faulty in flown:
        for t in range(EVERY // 2, len(states) - AHEAD, EVERY):
            if np.abs(states[t, W]).max() > MAX_RATE:
                continue
            dynamics.reset()
            first = max(t - frames, 0)
            for j in range(first, t + 1):
                dynamics.observe({"state": states[j]}, actions[j - 1] if j > first else None)
            end = dynamics.rollout(torch.from_numpy(states[t]), torch.from_numpy(actions[t : t + AHEAD])[None])[
                0, -1
            ].numpy()
            truth = states[t + AHEAD]
            errors["fault" if faulty else "none"].append(
                (
                    np.abs(end[W] - truth[W]).mean(),
                    np.abs(end[V] - truth[V]).mean(),
                    np.abs(states[t, W] - truth[W]).mean(),
                )
            )
    return {
        k: {
            "windows": len(v),
            "rate_mae": float(np.mean([x[0] for x in v])),
            "velocity_mae": float(np.mean([x[1] for x in v])),
            "holding_rate_mae": float(np.mean([x[2] for x in v])),
        }
        for k, v in errors.items()
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", help="a run trained on the dynamic tier: its held-out validation episodes are scored")
    ap.add_argument("dataset", help="the dynamic-tier dataset the run was trained on")
    ap.add_argument("--frames", type=int, nargs="+", default=[10, 20, 40, 80])
    ap.add_argument("--ridge", type=float, nargs="+", default=[1e-6, 1e-5, 1e-4, 1e-3])
    ap.add_argument("--inferred", action="store_true", help="also the fit under RUN/body's learned prior")
    ap.add_argument("--json", type=Path, help="write the figures here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    held = read_run_config(args.run).validation.episodes
    flown = list(flown_episodes(args.dataset, sorted(held)).values())
    sim = SimConfig(render=False)
    rows = [{"frames": 0, "ridge": None, **scores(FittedBodyDynamics(sim, frames=1, ridge=1.0), flown, 0)}]
    rows += [
        {"frames": f, "ridge": r, **scores(FittedBodyDynamics(sim, frames=f, ridge=r), flown, f)}
        for f in args.frames
        for r in args.ridge
    ]
    if args.inferred:
        inference, learned = load_inference(args.run)
        rows += [
            {
                "frames": f,
                "ridge": "inferred",
                **scores(InferredBodyDynamics(inference, learned, sim, frames=f), flown, f),
            }
            for f in args.frames
            if f <= learned.frames  # the histories it was trained on
        ]
    print(f"{len(held)} validation episodes of {args.dataset}; errors {AHEAD} frames ahead (rad/s, m/s)")
    print("frames  ridge   | fault: rate  velocity  (windows) | no fault: rate  velocity  (windows)")
    for row in rows:
        f, n = row["fault"], row["none"]
        ridge = {None: "design", "inferred": "learned"}.get(row["ridge"]) or f"{row['ridge']:.0e}"
        print(
            f"{row['frames']:>6}  {ridge:>6}  | {f['rate_mae']:.3f}  {f['velocity_mae']:.3f}  ({f['windows']})"
            f" | {n['rate_mae']:.3f}  {n['velocity_mae']:.3f}  ({n['windows']})"
        )
    hold = rows[0]
    print(
        f"holding the rate: fault {hold['fault']['holding_rate_mae']:.3f}, no fault {hold['none']['holding_rate_mae']:.3f} rad/s"
    )
    if args.json:
        args.json.write_text(
            json.dumps({"run": str(args.run), "dataset": str(args.dataset), "ahead": AHEAD, "rows": rows}, indent=1)
            + "\n"
        )


if __name__ == "__main__":
    main()
