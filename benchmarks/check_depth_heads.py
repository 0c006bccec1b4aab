"""A run's depth heads side by side on one dataset's frames: which sees the obstacles the planner needs.

    python benchmarks/check_depth_heads.py RUN DATASET [--heads stage1 refit dynamic] [--split val]
        [--frames 4000] [--seed 1] [--json X.json]

Scores each head ``--heads`` names (stage1: Stage I's; refit: RUN/depth; NAME: RUN/depth-NAME,
``orbitmodel depth --name``) on the same ``--frames`` random frames of DATASET's ``--split`` (val:
the run's validation episode numbers; test) against their true depth: MAE, and by band of true
distance the share of cells missed (predicted at or beyond the planner's 10 m range), and the
share of far cells brought inside it (phantom obstacles). With seed 1 and the refit's
--test-frames, the frames are those its own before/after table scored. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json

import torch

from orbitdata.cli.errors import run_script, script_help
from orbitmodel.data import EVAL_SPLITS
from orbitmodel.plan.depth_bands import band_label
from orbitmodel.plan.depth_refit import score_heads


def main() -> None:
    parser = argparse.ArgumentParser(description=script_help(__doc__))
    parser.add_argument("run", help="a trained run")
    parser.add_argument("dataset", help="an orbitdata dataset of the run's image size")
    parser.add_argument("--heads", nargs="+", default=["stage1", "refit"], help="stage1, refit or NAMEs")
    parser.add_argument("--split", default="val", choices=EVAL_SPLITS)
    parser.add_argument("--frames", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", help="write the scores here")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    scores = score_heads(args.run, args.dataset, args.heads, args.split, args.frames, args.seed)
    first = next(iter(scores.values()))
    print(f"{args.frames} {args.split} frames of {args.dataset}; missed: predicted at or beyond {first['range_m']:g} m")
    print(f"{'band':>9} {'cells':>8} " + " ".join(f"{name + ' MAE / missed':>24}" for name in scores))
    for i, band in enumerate(first["bands"]):
        cells = " ".join(
            f"{s['bands'][i]['mae_m']:>13.2f} m {100 * s['bands'][i]['missed']:>6.1f} %" for s in scores.values()
        )
        print(f"{band_label(band):>9} {band['cells']:>8} {cells}")
    print(f"{'all':>9} {'':>8} " + " ".join(f"{s['mae_m']:>13.2f} m {'':>8}" for s in scores.values()))
    print(f"{'phantom':>9} {'':>8} " + " ".join(f"{100 * s['phantom']:>22.2f} %" for s in scores.values()))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "run": args.run,
                    "dataset": args.dataset,
                    "split": args.split,
                    "frames": args.frames,
                    "seed": args.seed,
                    "heads": scores,
                },
                f,
                indent=2,
            )
            f.write("\n")


if __name__ == "__main__":
    run_script(main)
