"""Estimate the wall time of `TIER=dynamic bash scripts/reproduce_model.sh` from flown grids.

The chain flies about twenty grids on each of six seeds. This script reads the grids already
flown on the test seeds (docs/results/dynamic/{grid,static-run}/seed{3,4,5}/PILOT.json) and
estimates each one's wall time from its own records: the sum over its episodes of frames times the
median control step (divided by the batch size, whose step serves the whole batch), at the
batch size and beside whatever shared the cores when it was flown. The chain flies two grids at a
time, so half the sum over its grids estimates their wall time. Left out: the training steps, the
expert's and the Diffusion Policy's grids (which record no control-step times), the time outside
the control step, and a pair waiting for its slower grid.

    python benchmarks/estimate_tier_chain.py [--results docs/results/dynamic] [--seeds 6]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

# (folder, pilot) for every grid the chain flies on each seed, timed on the test seeds 3-5 (the same
# list as scripts/reproduce_model.sh flies: tests/cli/test_usage_errors.py holds the two together)
EVERY_SEED = [
    ("grid", "planner-imagined"),
    ("grid", "planner-tracker"),
    ("grid", "oracle-true"),
    ("grid", "oracle-frozen"),
    ("grid", "oracle-nominal"),
    ("grid", "oracle-learned-dyn"),
    ("grid", "planner-fitted-tracker"),
    ("grid", "planner-fitted-imagined"),
    ("grid", "oracle-fitted"),
    ("grid", "planner-inferred-tracker"),
    ("grid", "oracle-inferred"),
    ("grid", "planner-corrected-tracker"),
    ("grid", "oracle-learned-dyn-corrected"),
    ("static-run", "planner-tracker"),
    ("static-run", "planner-corrected-tracker-depth-dynamic"),
    ("static-run", "oracle-learned-dyn-corrected"),
    ("static-run", "oracle-true-dyn-depth-dynamic-tracker"),
    ("static-run", "oracle-true-dyn-sensor-tracker"),
    ("static-run", "planner-corrected-tracker-depth-dynamic-k128"),
    ("static-run", "planner-corrected-tracker-depth-dynamic-k256"),
]
# and the one it flies on validation seeds 0-2 alone, timed there: the static run corrected, on its own depth head
VALIDATION_ONLY = ("static-run", "planner-corrected-tracker")


def grid_seconds(path: Path) -> tuple[float, int]:
    """A grid's estimated wall seconds and its batch size, from its episodes' control steps."""
    grid = json.loads(path.read_text())
    batch = grid.get("batch") or 1
    steps = sum(e["frames"] * e["step_ms_median"] for e in grid["episodes"]) / 1000.0
    return steps / batch, batch


def row(results: Path, folder: str, pilot: str, seeds: tuple[int, ...]) -> list[float]:
    """Print one pilot's estimated seconds on each seed; return them."""
    measured = [grid_seconds(results / folder / f"seed{s}" / f"{pilot}.json") for s in seeds]
    batches = ",".join(str(b) for b in sorted({b for _, b in measured}))
    label = f"{folder}/{pilot} (seeds {'/'.join(map(str, seeds))})"
    print(f"{label:<72} {batches:>5} {'/'.join(f'{s:.0f}' for s, _ in measured):>16}")
    return [s for s, _ in measured]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("docs/results/dynamic"))
    parser.add_argument("--seeds", type=int, default=6, help="seeds the chain flies (0-5)")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds {args.seeds}: give the number of seeds the chain flies, 1 or more")
    if not (args.results / "static-run").is_dir():
        print(
            f"estimate_tier_chain.py: {args.results}/static-run is not there; give --results the tier's results folder",
            file=sys.stderr,
        )
        return 2
    needed = [(f, p, (3, 4, 5)) for f, p in EVERY_SEED] + [(*VALIDATION_ONLY, (0, 1, 2))]
    missing = [
        path
        for f, p, seeds in needed
        for s in seeds
        if not (path := args.results / f / f"seed{s}" / f"{p}.json").is_file()
    ]
    if missing:
        print(
            f"estimate_tier_chain.py: {missing[0]} is not there; fly that grid or give --results another folder",
            file=sys.stderr,
        )
        return 2
    print(f"{'grid':<72} {'batch':>5} {'seconds':>16}")
    per_seed = sum(statistics.fmean(row(args.results, f, p, (3, 4, 5))) for f, p in EVERY_SEED)
    validation = row(args.results, *VALIDATION_ONLY, (0, 1, 2))
    grids = per_seed * args.seeds + sum(validation[: args.seeds])
    print(f"grid seconds per seed: {per_seed:,.0f}; all {args.seeds} seeds with the validation-only grid: {grids:,.0f}")
    print(f"two at a time: {grids / 2:,.0f} s ({grids / 2 / 3600:.1f} h) of wall time for the grids")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
