"""Benchmark the windowed loader on a 224 px dataset: windows/s, peak memory, and two ratios.

    python benchmarks/bench_loader.py [DATASET] [--episodes 30] [--batch-size 64] [--batches 10]

Without DATASET, a small 224 px dataset is generated (or reused) under ``--out``. Each figure is
measured in a fresh subprocess over the same windows (sampler seed 0, epoch 0), so its peak
memory is that configuration's own. Columns: the world model's (image, depth_low, state,
action, collision, success; no full-resolution depth). m = 8, n = 12, batch 64 by default.

* decode-only bound: only ``cv2.imdecode`` of the windows' RGB frames, bytes extracted first.
* loader, 0 and 2 workers: ``DataLoader(load_windows(...), batch_size, sampler=ds.sampler(seed=0),
  collate_fn=collate_windows)``.
* naive, 0 and 2 workers: ``load_dataset(...).with_format("torch")`` and ``ds[row:row + T]``
  per window (images decoded by ``datasets`` with Pillow), in a DataLoader. "all columns" is
  that code as written, which also decodes full-resolution depth; "same columns" passes the
  loader's columns to ``with_format`` (the like-for-like comparison).

Throughput is steady state: the first ``--warmup`` batches (worker start-up, the first
allocations of batch memory) are not timed.
Configurations run in interleaved rounds and each figure is the best of ``--repeats``, since
other processes may share the machine. Peak memory is ``VmHWM``, the peak resident set, of the
measuring process and of its largest DataLoader worker (read while it still runs); pages
shared with the parent after ``fork`` and memory-mapped Arrow pages count in it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from orbitdata import schema as S  # noqa: E402
from orbitdata.cli.errors import child_reason, run_script

COLUMNS = [S.IMAGE, S.DEPTH_LOW, S.STATE, S.ACTION, S.COLLISION, S.SUCCESS]  # the world model's inputs/targets
BOUND = "decode-only bound (cv2.imdecode)"
CONFIGS = {  # name: (mode, DataLoader workers)
    BOUND: ("decode", 0),
    "loader, 0 workers": ("loader", 0),
    "loader, 2 workers": ("loader", 2),
    "naive same columns, 0 workers": ("naive", 0),
    "naive same columns, 2 workers": ("naive", 2),
    "naive all columns, 0 workers": ("naive-all", 0),
    "naive all columns, 2 workers": ("naive-all", 2),
}


def ensure_dataset(out: Path, episodes: int, size: int) -> Path:
    """Generate (or resume, or reuse) a ``size`` px dataset of ``episodes`` episodes in ``out``."""
    from orbitdata.config import GenerationConfig
    from orbitdata.write.generate import generate

    cfg = GenerationConfig()
    cfg = cfg.replace(
        dataset={"episodes": episodes, "seed": 0, "test_fraction": 0.2},
        sim={"camera": cfg.sim.camera.__class__(image_size=size)},
    )
    if not (out / S.INFO_PATH).exists():
        print(f"generating {episodes} episodes at {size} px into {out} ...", flush=True)
    generate(out, cfg, workers=1)
    return out


def vm_hwm_mb(pid: int | str = "self") -> float:
    """Peak resident memory of a process (``VmHWM``; unlike ``ru_maxrss``, not inherited through exec)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:  # the process has exited
        return 0.0
    kb = next((int(line.split()[1]) for line in status.splitlines() if line.startswith("VmHWM:")), 0)
    return round(kb / 1024, 1)


def windows(args):
    """The loader's dataset and the windows every configuration reads, in sampler order."""
    from orbitdata.load import load_windows

    ds = load_windows(
        args.dataset, context=args.context, horizon=args.horizon, columns=COLUMNS, cache_dir=args.cache_dir
    )
    order = list(ds.sampler(seed=0))[: args.batch_size * (args.warmup + args.batches)]
    return ds, order


def timed(batches, warmup: int) -> dict:
    """Windows/s over every batch but the first ``warmup`` (start-up: workers, first allocations)."""
    it = iter(batches)
    for _ in range(warmup):
        next(it)
    t0 = time.perf_counter()
    workers = [w.pid for w in getattr(it, "_workers", [])]  # torch's worker processes, if any
    n, worker_peak = 0, 0.0
    for batch in it:
        n += len(batch[S.ACTION])
        worker_peak = max([worker_peak, *(vm_hwm_mb(pid) for pid in workers)])  # before they exit
    seconds = time.perf_counter() - t0
    return {"windows_per_s": n / seconds, "windows": n, "peak_worker_rss_mb": worker_peak}


def measure_loader(args) -> dict:
    from torch.utils.data import DataLoader

    from orbitdata.load import collate_windows

    ds, order = windows(args)
    return timed(
        DataLoader(ds, batch_size=args.batch_size, sampler=order, num_workers=args.workers, collate_fn=collate_windows),
        args.warmup,
    )


def measure_decode(args) -> dict:
    import cv2
    import numpy as np

    ds, order = windows(args)
    table = ds.steps.data.table
    blobs = []
    for i in order[args.batch_size * args.warmup :]:  # the loader's timed windows
        col = table.column(S.IMAGE).slice(int(ds.index.row[i]), int(ds.index.n_real[i]))
        blobs.append([np.frombuffer(b, np.uint8) for b in col.combine_chunks().field("bytes").to_pylist()])
    t0 = time.perf_counter()
    for frames in blobs:
        for blob in frames:
            cv2.imdecode(blob, cv2.IMREAD_COLOR_RGB)
    return {"windows_per_s": len(blobs) / (time.perf_counter() - t0), "windows": len(blobs)}


class NaiveWindows:
    """What a user would write first: ``with_format("torch")`` and one slice of rows per window."""

    def __init__(self, steps, rows: list[int], length: int):
        self.steps, self.rows, self.length = steps, rows, length

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, i: int) -> dict:
        return self.steps[self.rows[i] : self.rows[i] + self.length]


def measure_naive(args, all_columns: bool = False) -> dict:
    from datasets import load_dataset
    from torch.utils.data import DataLoader

    ds, order = windows(args)
    steps = load_dataset(str(args.dataset), split="train", cache_dir=args.cache_dir)
    if all_columns:
        steps = steps.with_format("torch")
    else:
        steps = steps.with_format("torch", columns=COLUMNS + [S.EPISODE_INDEX, S.FRAME_INDEX])
    rows = [int(ds.index.row[i]) for i in order][: args.batch_size * (1 + args.naive_batches)]
    naive = NaiveWindows(steps, rows, ds.config.length)
    return timed(DataLoader(naive, batch_size=args.batch_size, num_workers=args.workers), 1)


def run_once(args, mode: str, workers: int) -> dict:
    cmd = [
        sys.executable,
        __file__,
        str(args.dataset),
        "--measure",
        mode,
        "--workers",
        str(workers),
        "--batch-size",
        str(args.batch_size),
        "--batches",
        str(args.batches),
        "--warmup",
        str(args.warmup),
        "--context",
        str(args.context),
        "--horizon",
        str(args.horizon),
        "--cache-dir",
        args.cache_dir,
        "--naive-batches",
        str(args.naive_batches),
    ]
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"error: {mode} with {workers} workers failed: {child_reason(out.stderr, out.returncode)}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_all(args) -> dict[str, dict]:
    """Interleaved rounds of every configuration: throughput is the best round, memory the largest."""
    best: dict[str, dict] = {}
    for _ in range(args.repeats):
        for name, (mode, workers) in CONFIGS.items():
            r = run_once(args, mode, workers)
            if name in best:
                peaks = {k: max(best[name][k], r[k]) for k in ("peak_rss_mb", "peak_worker_rss_mb")}
                r = max(best[name], r, key=lambda x: x["windows_per_s"]) | peaks
            best[name] = r
    return best


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", nargs="?", type=Path, help="dataset folder; default: generate one under --out")
    p.add_argument("--out", type=Path, default=Path("/tmp/orbitdata-bench-224"))
    p.add_argument("--episodes", type=int, default=30)
    p.add_argument("--image-size", type=int, default=224)
    p.add_argument("--context", type=int, default=8)
    p.add_argument("--horizon", type=int, default=12)
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--batches", type=int, default=10, help="timed loader batches")
    p.add_argument("--warmup", type=int, default=2, help="untimed loader batches first (steady state after)")
    p.add_argument("--naive-batches", type=int, default=2, help="timed naive batches, after one (it is slow)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--cache-dir", default=None, help="datasets cache (default: .hf-cache-bench next to the dataset)")
    p.add_argument("--measure", choices=["loader", "decode", "naive", "naive-all"], help=argparse.SUPPRESS)
    p.add_argument("--workers", type=int, default=0, help=argparse.SUPPRESS)
    args = p.parse_args()

    if args.measure:
        measure = {
            "loader": measure_loader,
            "decode": measure_decode,
            "naive": measure_naive,
            "naive-all": lambda a: measure_naive(a, all_columns=True),
        }[args.measure]
        result = measure(args)
        print(json.dumps({"peak_worker_rss_mb": 0.0} | result | {"peak_rss_mb": vm_hwm_mb()}))
        return

    args.dataset = args.dataset or ensure_dataset(args.out, args.episodes, args.image_size)
    args.cache_dir = args.cache_dir or str(args.dataset.resolve().parent / ".hf-cache-bench")
    ds, _ = windows(args)  # builds the Arrow cache once, outside the timings
    info = json.loads((args.dataset / S.INFO_PATH).read_text())
    print(f"dataset {args.dataset}: {info['features'][S.IMAGE]['shape'][0]} px, {ds}")
    print(f"m={args.context}, n={args.horizon}, batch {args.batch_size}, columns {COLUMNS}, {os.cpu_count()} CPUs")

    results = run_all(args)
    width = max(map(len, results)) + 1
    print(f"\n{'':{width}s} {'windows/s':>10s} {'peak RSS MB':>12s} {'worker peak MB':>15s}")
    for name, r in results.items():
        print(f"{name:{width}s} {r['windows_per_s']:10.1f} {r['peak_rss_mb']:12.1f} {r['peak_worker_rss_mb']:15.1f}")
    rate = {name: r["windows_per_s"] for name, r in results.items()}

    def ratios(baseline: str) -> str:
        return ", ".join(f"{w} workers {rate[f'loader, {w} workers'] / rate[baseline.format(w=w)]:.2f}" for w in (0, 2))

    print(f"\nloader / decode-only bound:          {ratios(BOUND)}  (goal >= 0.7)")
    print(f"loader / naive, same columns:        {ratios('naive same columns, {w} workers')}")
    print(f"loader / naive as written (all cols): {ratios('naive all columns, {w} workers')}  (goal >= 5)")


if __name__ == "__main__":
    run_script(main)
