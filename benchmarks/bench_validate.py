"""Validation throughput (MB/s, frames/s; quick and full) and peak memory, against generation.

    python benchmarks/bench_validate.py /path/to/dataset [...]        # datasets you already have
    python benchmarks/bench_validate.py --episodes 800 --image-size 224  # generate N/4 and N first

Each validation runs in a fresh process (all cores unless --workers); peak memory is the
VmHWM of the driver and of the largest worker (Linux /proc), reported separately. With no DIR, two datasets of
N/4 and N episodes are generated with the same settings (timed: that is the generation rate), so
the table shows whether memory stays flat as the dataset grows. For DIRs, the generation rate is
measured on --sample-episodes episodes of the first one's config (or given with --generation-fps).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from orbitdata.cli.errors import run_script

CHILD = r"""
import json, os, sys, threading, time
from orbitdata.validate import ValidateOptions, validate

def hwm_mb(pid="self"):  # peak resident set of a live process (getrusage would inherit the parent's peak)
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmHWM")) / 1024

def children():
    pids = set()
    for task in os.listdir("/proc/self/task"):
        try:
            pids |= set(open(f"/proc/self/task/{task}/children").read().split())
        except OSError:
            pass
    return pids

peak, done = [0.0], threading.Event()
def sample():  # workers exit with the pool: read their peaks while they live
    while not done.wait(0.05):
        for pid in children():
            try:
                peak[0] = max(peak[0], hwm_mb(pid))
            except (OSError, StopIteration):
                pass
threading.Thread(target=sample, daemon=True).start()
t = time.monotonic()
report = validate(sys.argv[1], ValidateOptions(quick=sys.argv[2] == "quick", workers=int(sys.argv[3])))
seconds = time.monotonic() - t
done.set()
print(json.dumps({"ok": report.ok, "failed": report.failed(), "seconds": seconds, "bytes": report.bytes,
                  "frames": report.frames, "workers": report.workers, "driver_rss_mb": hwm_mb(),
                  "worker_rss_mb": peak[0]}))
"""


def generate(out: Path, episodes: int, image_size: int, workers: int, config: dict | None = None) -> float:
    """Generate a dataset; returns frames per second of the whole run (fly, render, encode, shard)."""
    from orbitdata.config import GenerationConfig
    from orbitdata.write.generate import generate as run

    cfg = GenerationConfig.from_dict(config) if config else GenerationConfig()
    cfg = cfg.replace(dataset={"episodes": episodes})
    if image_size:
        cfg = cfg.replace(sim={"camera": dataclasses.replace(cfg.sim.camera, image_size=image_size)})
    start = time.monotonic()
    info = run(out, cfg, workers=workers)
    return info.counts["frames"] / (time.monotonic() - start)


def measure(root: Path, mode: str, workers: int) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(root), mode, str(workers)], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("datasets", nargs="*", type=Path)
    parser.add_argument("--episodes", type=int, default=80, help="episodes to generate when no DIR is given")
    parser.add_argument("--image-size", type=int, default=64)
    parser.add_argument("--workers", type=int, default=0, help="0 = all cores (generation and validation)")
    parser.add_argument(
        "--sample-episodes",
        type=int,
        default=48,
        help="episodes generated (with DIR's config) to rate generation; startup is amortised",
    )
    parser.add_argument(
        "--generation-fps",
        type=float,
        default=None,
        help="known generation rate (frames/s) for DIR, e.g. from `orbitdata generate`'s bar",
    )
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    cores = os.cpu_count() or 1
    workers = args.workers or cores

    tmp = tempfile.TemporaryDirectory(prefix="bench_validate_")
    gen_fps: float | None = None
    datasets = list(args.datasets)
    if not datasets:
        for n in (max(1, args.episodes // 4), args.episodes):
            path = Path(tmp.name) / f"orbit_{n}"
            print(f"generating {n} episodes at {args.image_size} px with {workers} workers ...", flush=True)
            gen_fps = generate(path, n, args.image_size, workers)
            datasets.append(path)
    elif args.generation_fps:
        gen_fps = args.generation_fps
    else:
        config = json.loads((datasets[0] / "meta" / "info.json").read_text())["config"]
        print(f"timing generation of {args.sample_episodes} episodes with {datasets[0]}'s config ...", flush=True)
        gen_fps = generate(Path(tmp.name) / "sample", args.sample_episodes, 0, workers, config)

    print(f"\ngeneration: {gen_fps:,.0f} frames/s with {workers} workers on {cores} cores\n")
    header = (
        f"{'dataset':<28} {'mode':<6} {'MB':>8} {'frames':>9} {'s':>7} {'MB/s':>8} {'frames/s':>10} "
        f"{'x gen':>6} {'driver MB':>9} {'worker MB':>9}  result"
    )
    print(header)
    print("-" * len(header))
    for root in datasets:
        for mode in ("quick", "full"):
            r = measure(root, mode, args.workers)
            fps = r["frames"] / r["seconds"]
            print(
                f"{root.name[:28]:<28} {mode:<6} {r['bytes'] / 1e6:>8.1f} {r['frames']:>9,} {r['seconds']:>7.2f} "
                f"{r['bytes'] / 1e6 / r['seconds']:>8.1f} {fps:>10,.0f} {fps / gen_fps:>6.1f} "
                f"{r['driver_rss_mb']:>9.0f} {r['worker_rss_mb']:>9.0f}  "
                f"{'valid' if r['ok'] else 'INVALID: ' + ','.join(r['failed'])} ({r['workers']} workers)",
                flush=True,
            )
    print("\nx gen: validation frames/s over generation frames/s (goal for full: >= 10).")
    tmp.cleanup()


if __name__ == "__main__":
    run_script(main)
