"""Plot a policy run's action MSE and success against training steps, from its snapshots.

    bash scripts/snapshot_checkpoints.sh RUN 2000 SNAPS          # while RUN trains
    for s in SNAPS/step-*; do
      orbitmodel eval policy $s DATA --split val --max-windows 2000 --json > $s/eval_val.json
      orbitmodel eval closed-loop $s --obstacles 1 --speeds 1,2 --episodes 20 --seed 1 --set action_steps=2 --json $s/fly.json
    done
    python scripts/policy_curve.py SNAPS --out curve.png --json curve.json

Each ``SNAPS/step-N`` may hold ``eval_val.json`` (``eval policy --json``: the executed actions' MSE
against the mean action's) and ``fly.json`` (``eval closed-loop --json``); the curve shows what
is there: the MSE ratio overall and per goal-distance band, and the success rate with its 95 %
Wilson interval.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from orbitdata.cli.errors import run_script, script_help


def read_points(folder: Path) -> list[dict]:
    from orbitmodel.evaluate.success import report_totals, wilson

    points = []
    for snap in sorted(folder.glob("step-*"), key=lambda p: int(re.sub(r"\D", "", p.name) or 0)):
        point: dict = {"step": int(snap.name.split("-")[1])}
        ev, fly = snap / "eval_val.json", snap / "fly.json"
        if ev.is_file() and ev.stat().st_size:
            e = json.loads(ev.read_text())
            point.update(
                split=e["split"],
                mse=e["policy"],
                mean_action_mse=e["mean_action"],
                ratio=e["ratio"],
                bands={
                    (f"> {b['from_m']:g}" if b["to_m"] is None else f"{b['from_m']:g}-{b['to_m']:g}"): b["ratio"]
                    for b in e["per_band"]
                },
            )
        if fly.is_file():
            f = json.loads(fly.read_text())
            k, n = report_totals(f)
            point.update(
                success=k,
                episodes=n,
                success_ci=list(wilson(k, n)),
                flight_seed=f["seed"],
                settings=[(s["obstacles"], s["speed"]) for s in f["settings"]],
            )
        if len(point) > 1:
            points.append(point)
    return points


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=script_help(__doc__))
    parser.add_argument("snapshots", type=Path, help="folder of step-N snapshot runs")
    parser.add_argument("--out", type=Path, required=True, help="PNG to write")
    parser.add_argument("--json", type=Path, help="write the points here too")
    parser.add_argument(
        "--mark",
        type=int,
        action="append",
        default=[],
        help="a dotted line at this step, e.g. where the run was trained on (--resume --extend)",
    )
    args = parser.parse_args(argv)
    points = read_points(args.snapshots)
    if not points:
        print(
            f"error: no step-N folder in {args.snapshots} holds eval_val.json or fly.json; see --help", file=sys.stderr
        )
        return 2
    from orbitmodel.extras import pyplot

    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    mse = [p for p in points if "ratio" in p]
    if mse:
        a.plot([p["step"] for p in mse], [p["ratio"] for p in mse], "o-", color="k", label="all frames")
        for band in mse[0]["bands"]:
            a.plot([p["step"] for p in mse], [p["bands"][band] for p in mse], ".--", label=f"{band} m to goal")
        a.axhline(0.5, color="grey", lw=0.8)
        a.set(xlabel="training step", ylabel="action MSE / mean action's", title=f"open loop ({mse[0]['split']} split)")
        a.legend(fontsize=7)
    fly = [p for p in points if "success" in p]
    if fly:
        steps = [p["step"] for p in fly]
        rate = [100 * p["success"] / p["episodes"] for p in fly]
        low = [r - 100 * p["success_ci"][0] for r, p in zip(rate, fly)]
        high = [100 * p["success_ci"][1] - r for r, p in zip(rate, fly)]
        b.errorbar(steps, rate, yerr=[low, high], fmt="o-", color="C3", capsize=3)
        b.set(
            xlabel="training step",
            ylabel="success %, 95 % CI",
            ylim=(0, 100),
            title=f"closed loop: {'/'.join(sorted({str(n) for n, _ in fly[0]['settings']}))} obstacle(s), "
            f"{fly[0]['episodes']} episodes, seed {fly[0]['flight_seed']}",
        )
    for axis in (a, b):
        for step in args.mark:
            axis.axvline(step, color="grey", ls=":", lw=1)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    if args.json:
        args.json.write_text(json.dumps(points, indent=2) + "\n")
    for p in points:
        print(
            p["step"],
            *(f"{k}={p[k]:.3f}" for k in ("ratio",) if k in p),
            *(f"success={p['success']}/{p['episodes']}",) if "success" in p else (),
        )
    return 0


if __name__ == "__main__":
    run_script(main)
