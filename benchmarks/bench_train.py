"""Benchmark Stage I training: windows/s, the share of step time spent waiting for data, peak memory.

    python benchmarks/bench_train.py DATASET [--preset cpu] [--steps 40] [--workers 0 1]

Each configuration trains ``--steps`` steps of the preset in a fresh subprocess (a throwaway
run folder) through the real loop (``orbitmodel.train.stage1.train_world_model``). The first
``--warmup`` steps (allocations, the first batches) are excluded from the throughput. "data
wait" is the time the loop blocks on the DataLoader over the time of the whole step, as the
loop measures it. Peak memory is the process's ``ru_maxrss`` (workers excluded; with workers,
their own peak is printed too).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile

from orbitdata.cli.errors import child_reason, run_script

os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")


def measure(dataset: str, preset: str, steps: int, warmup: int, workers: int) -> dict:
    from orbitmodel.config import get_preset
    from orbitmodel.train.stage1 import Stage1Request, train_world_model

    p = get_preset(preset).with_train(max_steps=steps, num_workers=workers, log_every=1, save_every=10**9)
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        result = train_world_model(
            Stage1Request(dataset=dataset, preset=p, out=f"{tmp}/run", device="cpu"), on_log=records.append
        )
    steady = [r for r in records if r["step"] > warmup]
    seconds = steady[-1]["elapsed_s"] - records[warmup - 1]["elapsed_s"]
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return {
        "preset": preset,
        "workers": workers,
        "steps": result.steps,
        "batch": p.train.loop.batch_size,
        "window": p.train.window,
        "windows_per_s": len(steady) * p.train.loop.batch_size / seconds,
        "frames_per_s": len(steady) * p.train.loop.batch_size * p.train.window / seconds,
        "seconds_per_step": seconds / len(steady),
        "data_wait": result.data_wait,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "peak_worker_rss_mb": children if workers else 0.0,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset")
    ap.add_argument("--preset", default="cpu")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--workers", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)  # internal: measure one config, print JSON
    args = ap.parse_args()
    if not 1 <= args.warmup < args.steps:
        ap.error(
            f"--warmup {args.warmup} --steps {args.steps}: give 1 <= warmup < steps (the steps after the warm-up are timed)"
        )
    if args.one is not None:
        print(json.dumps(measure(args.dataset, args.preset, args.steps, args.warmup, args.one)))
        return
    print(
        f"Stage I training, preset {args.preset}, {args.steps} steps ({args.warmup} warm-up) on {args.dataset}, "
        f"torch threads {os.environ.get('OMP_NUM_THREADS', 'default')}"
    )
    for workers in args.workers:
        out = subprocess.run(
            [
                sys.executable,
                __file__,
                args.dataset,
                "--preset",
                args.preset,
                "--steps",
                str(args.steps),
                "--warmup",
                str(args.warmup),
                "--one",
                str(workers),
            ],
            capture_output=True,
            text=True,
        )
        if out.returncode:  # the child's own one-line reason (a missing dataset, a bad preset)
            raise SystemExit(f"error: workers {workers}: {child_reason(out.stderr, out.returncode)}")
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(
            f"  workers {workers}: {r['windows_per_s']:6.1f} windows/s ({r['frames_per_s']:6.0f} frames/s, "
            f"{r['seconds_per_step']:.2f} s/step at batch {r['batch']} x {r['window']} frames), "
            f"data wait {100 * r['data_wait']:.1f} % of step time (goal < 10 %), peak RSS {r['peak_rss_mb']:.0f} MB"
            + (f", worker {r['peak_worker_rss_mb']:.0f} MB" if workers else "")
        )


if __name__ == "__main__":
    run_script(main)
