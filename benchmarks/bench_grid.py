"""Grid throughput: the unbatched flight against lockstep batches (``eval closed-loop --batch N``).

    python benchmarks/bench_grid.py [--run RUN] [--policy RUN] [--batches 4,8,16] [--episodes 10]
        [--seed 2] [--max-steps 300] [--work DIR] [--no-policy | --no-planner] [--one-process]
        [--baseline RUN] [--set KEY=VALUE ...]

Flies the same 40 episodes (1 and 3 obstacles at 1 and 2 m/s, ``--episodes`` each, grid seed
``--seed``: a validation seed) with the planner (preset cpu) and with the Diffusion Policy
(flight preset cpu), side by side in one run, and prints episodes per hour on this machine:

* unbatched: two processes with one torch thread each (``--speeds 1`` and ``--speeds 2``), as
  ``scripts/reproduce_model.sh`` flies two grids at a time: today's way to keep 2 cores busy;
* ``--batch N`` in the same two processes (and with ``--one-process`` in one process with two
  threads, which loses to two single-threaded ones wherever other work shares the cores);

each with its wall time, episodes per hour and ratio to the unbatched flight; the CPU seconds its
processes used per episode and that ratio (the work itself, which other load on the machine does
not change as it changes the wall time); the outcome flips against the unbatched flight (``eval
flips``), the episodes flown identically (frames and closest approach) and the pooled success. ``--run`` is a Stage I run with its probe (the planner flies it); without one, an
untrained run of the ``cpu-step5`` sizes is built (one training step on a small dataset), and
``--policy`` likewise (an untrained ``cpu`` policy run): the weights do not change the work per
step, so the figures are throughput only and the outcomes are meaningless.

``--baseline RUN`` first flies another Stage I run unbatched, as the planner's first row: the
planner's ratios and flip counts are then against that flight (a smaller model's batches against the flown run's
unbatched flight), its own unbatched flight the second row. ``--set KEY=VALUE`` passes planner
settings to ``--run``'s flights, not the baseline's (``--set samples=256``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from orbitdata.cli.errors import child_reason, run_script, script_help

BIN = Path(sys.executable).parent
OBSTACLES, SPEEDS = "1,3", ("1", "2")


def run(*command) -> None:
    """Run a CLI step; on failure stop with the command and the last line it printed on stderr."""
    done = subprocess.run([str(c) for c in command], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode:
        why = child_reason(done.stderr, done.returncode)
        raise SystemExit(f"error: `{' '.join(map(str, command))}` failed: {why}")


def untrained_runs(work: Path, policy: bool, planner: bool = True) -> tuple[Path | None, Path | None]:
    """A small 64 px dataset, a cpu-step5 run and probe after one step each (``planner``), and a cpu
    policy after one (``policy``)."""
    data, wm, dp = work / "orbit64", work / "wm-cpu-step5", work / "dp-cpu"
    if not (data / "meta" / "info.json").is_file():
        run(BIN / "orbitdata", "generate", data, "--episodes", "8", "--image-size", "64", "--workers", "1")
    if planner and not (wm / "model.safetensors").is_file():
        run(BIN / "orbitmodel", "train", data, "--preset", "cpu-step5", "--out", wm, "--max-steps", "1", "--overwrite")
    if planner and not (wm / "probe" / "model.safetensors").is_file():
        run(
            BIN / "orbitmodel",
            "probe",
            wm,
            data,
            "--max-steps",
            "1",
            "--cache-windows",
            "0",
            "--batch-size",
            "8",
            "--overwrite",
        )
    if policy and not (dp / "model.safetensors").is_file():
        run(
            BIN / "orbitmodel",
            "train-policy",
            data,
            "--preset",
            "cpu",
            "--out",
            dp,
            "--max-steps",
            "1",
            "--batch-size",
            "8",
            "--overwrite",
        )
    return wm if planner else None, dp if policy else None


def fly(
    run_dir: Path, out: Path, args, parts: list[tuple[str, int]], batch: int, settings: tuple[str, ...] = ()
) -> tuple[float, float, dict]:
    """Fly the grid as ``parts`` (speeds, threads) in parallel processes, with ``settings`` as
    ``--set`` options; (wall seconds, CPU seconds, merged report)."""
    grid = ["--obstacles", OBSTACLES, "--episodes", str(args.episodes), "--seed", str(args.seed)]
    grid += ["--max-steps", str(args.max_steps), "--preset", "cpu", "--batch", str(batch)]
    grid += [option for setting in settings for option in ("--set", setting)]
    jsons = [out.with_name(f"{out.stem}-{i}.json") for i in range(len(parts))]
    logs = [path.with_suffix(".stderr") for path in jsons]  # a file each: no pipe to drain while they fly
    out.parent.mkdir(parents=True, exist_ok=True)
    for path in jsons:  # a killed benchmark's kept chunks: every flight here is timed whole
        path.with_suffix(".chunks.jsonl").unlink(missing_ok=True)
    start = time.perf_counter()
    procs = []
    for (speeds, threads), path, log in zip(parts, jsons, logs):
        with log.open("w") as stderr:
            procs.append(
                subprocess.Popen(
                    [BIN / "orbitmodel", "eval", "closed-loop", run_dir, *grid, "--speeds", speeds]
                    + ["--threads", str(threads), "--json", path],
                    stdout=subprocess.DEVNULL,
                    stderr=stderr,
                )
            )
    cpu = 0.0
    for p in procs:
        _, status, usage = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        cpu += usage.ru_utime + usage.ru_stime
    wall = time.perf_counter() - start
    for p, log in zip(procs, logs):
        if p.returncode:
            why = child_reason(log.read_text(), p.returncode)
            raise SystemExit(f"error: a flight of {run_dir} failed ({why}): {' '.join(map(str, p.args))}")
    reports = [json.loads(p.read_text()) for p in jsons]
    episodes = sorted(
        (e for r in reports for e in r["episodes"]), key=lambda e: (e["episode"], e["obstacles"], e["speed"])
    )
    return wall, cpu, {**reports[0], "episodes": episodes}


def compare(name: str, key: str, run_dir: Path, args, work: Path) -> None:
    from orbitmodel.evaluate.success import outcome_flips, wilson

    two = [(s, 1) for s in SPEEDS]  # two processes, one thread each
    one = [(",".join(SPEEDS), 2)]  # one process, two threads
    settings = tuple(args.set) if key == "planner" else ()
    rows, baseline = [], args.baseline if key == "planner" else None
    if baseline:
        flight = fly(baseline, work / f"{key}-baseline.json", args, two, 1)
        rows.append(("baseline, unbatched, 2 x 1 thread", *flight))
    flight = fly(run_dir, work / f"{key}-unbatched.json", args, two, 1, settings)
    rows.append(("unbatched, 2 processes x 1 thread", *flight))
    for n in args.batches:
        flight = fly(run_dir, work / f"{key}-b{n}-2x1.json", args, two, n, settings)
        rows.append((f"--batch {n}, 2 processes x 1 thread", *flight))
        if args.one_process:
            flight = fly(run_dir, work / f"{key}-b{n}-1x2.json", args, one, n, settings)
            rows.append((f"--batch {n}, 1 process x 2 threads", *flight))
    base_wall, base_cpu, base = rows[0][1:]
    total = len(base["episodes"])
    print(f"\n{name}: {total} episodes (obstacles {OBSTACLES}, speeds {','.join(SPEEDS)}, seed {args.seed})")
    if baseline:
        print(f"baseline: {baseline}, unbatched, the planner preset as it is; ratios and flips against it")
    print(
        f"{'flight':36s} {'wall s':>7s} {'episodes/h':>10s} {'ratio':>6s} {'CPU s/ep':>8s} {'ratio':>6s} "
        f"{'flips':>6s} {'same':>6s}  success [95 % CI]"
    )
    for label, wall, cpu, report in rows:
        flips = outcome_flips(base, report)
        wins = sum(e["outcome"] == "success" for e in report["episodes"])
        low, high = wilson(wins, total)
        print(
            f"{label:36s} {wall:7.1f} {3600 * total / wall:10.0f} {base_wall / wall:5.2f}x {cpu / total:8.2f} "
            f"{base_cpu / cpu:5.2f}x {flips['flips']:2d}/{total:<3d} {flips.get('identical', 0):2d}/{total:<3d}  "
            f"{100 * wins / total:.0f} % [{100 * low:.0f}, {100 * high:.0f}]"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("--run", type=Path, help="a Stage I run with its probe (default: an untrained cpu-step5 run)")
    ap.add_argument("--policy", type=Path, help="a Diffusion Policy run (default: an untrained cpu policy run)")
    ap.add_argument("--no-policy", action="store_true", help="fly the planner only")
    ap.add_argument("--no-planner", action="store_true", help="fly the policy only")
    ap.add_argument("--one-process", action="store_true", help="also fly each batch in one process on two threads")
    ap.add_argument("--batches", default="4,8,16", help="batch sizes N, comma-separated")
    ap.add_argument("--episodes", type=int, default=10, help="episodes per setting (4 settings)")
    ap.add_argument("--seed", type=int, default=2, help="the grid seed (2: a validation seed)")
    ap.add_argument("--max-steps", type=int, default=300, help="frames per episode at most")
    ap.add_argument(
        "--work", type=Path, help="folder for the untrained runs and the flights (default: a temporary one)"
    )
    ap.add_argument("--baseline", type=Path, help="a Stage I run flown unbatched first, the ratios' reference")
    ap.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="a planner setting for --run's flights"
    )
    args = ap.parse_args()
    if args.no_policy and args.no_planner:
        ap.error("--no-policy and --no-planner leave nothing to fly: give one of them")
    try:
        args.batches = [int(n) for n in args.batches.split(",")]
    except ValueError:
        ap.error(f"--batches {args.batches}: give whole numbers, comma-separated (4,8,16)")
    if args.no_planner and (args.baseline or args.set):
        ap.error("--baseline and --set are the planner's: leave out --no-planner")
    if min(args.batches) < 1:
        ap.error(f"--batches {','.join(map(str, args.batches))}: each batch size must be 1 or more")
    os.environ.setdefault("MUJOCO_GL", "egl")
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-grid-"))
    work.mkdir(parents=True, exist_ok=True)
    wm, dp = args.run, args.policy
    if (wm is None and not args.no_planner) or (dp is None and not args.no_policy):
        built_wm, built_dp = untrained_runs(
            work, policy=dp is None and not args.no_policy, planner=wm is None and not args.no_planner
        )
        flown = (("cpu-step5 world model and probe", wm, args.no_planner), ("cpu policy", dp, args.no_policy))
        untrained = [what for what, given, skipped in flown if not (given or skipped)]
        print(
            f"untrained {' and '.join(untrained)} (one training step, in {work}): throughput only, outcomes meaningless"
        )
        wm, dp = wm or built_wm, dp or built_dp
    print(
        f"{os.cpu_count()} cores (load average {os.getloadavg()[0]:.1f} at the start); every flight one after another"
    )
    if not args.no_planner:
        preset = f"preset cpu with {', '.join(args.set)}" if args.set else "preset cpu: K 32, H 50, history 2"
        compare(f"planner ({preset})", "planner", wm, args, work)
    if not args.no_policy:
        compare("diffusion policy (flight preset cpu)", "diffusion", dp, args, work)


if __name__ == "__main__":
    run_script(main)
