"""Generation throughput per core against the render-only bound, bytes per frame, and memory.

    python benchmarks/bench_generate.py [--episodes 24] [--image-size 224]

1. Render-only bound: one process renders RGB+depth frames of the same kind of scenes (no
   physics, no pilot, no encoding) -> frames/s.
2. End to end: `generate` with one worker (one core) -> frames/s, and the ratio to (1)
   (goal >= 0.8).
3. Bytes per frame of the finished dataset (goal <= 12 KB at 224 px).
4. Peak memory (max RSS) of a one-worker generation of N and 3N episodes in subprocesses:
   it should be flat in the number of episodes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("LP_NUM_THREADS", "1")  # one core, like one worker

from orbitdata.config import GenerationConfig  # noqa: E402
from orbitdata.dataset.generate import generate  # noqa: E402
from orbitdata.sim import CubeSatEnv  # noqa: E402

MEM_SCRIPT = """
import resource, sys, os
os.environ.setdefault("LP_NUM_THREADS", "1")
from orbitdata.config import GenerationConfig
from orbitdata.dataset.generate import generate
cfg = GenerationConfig.from_dict(__import__("json").loads(sys.argv[2]))
generate(sys.argv[1], cfg, workers=1)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def config(episodes: int, image_size: int) -> GenerationConfig:
    cfg = GenerationConfig()
    return cfg.replace(
        dataset={"episodes": episodes, "seed": 123},
        sim={"camera": dataclasses.replace(cfg.sim.camera, image_size=image_size)},
    )


def render_bound(cfg: GenerationConfig, frames: int) -> float:
    env = CubeSatEnv(cfg.sim, cfg.scenario)
    done, seed, start = 0, 0, None
    while done < frames:
        env.reset(seed=seed)
        seed += 1
        for _ in range(50):
            env._observe()
            done += 1
            if start is None:  # after the first frame: GL start-up is not rendering
                start, done = time.perf_counter(), 0
    return done / (time.perf_counter() - start)


def peak_rss_mb(episodes: int, image_size: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        cfg = json.dumps(config(episodes, image_size).to_dict())
        out = subprocess.run([sys.executable, "-c", MEM_SCRIPT, str(Path(tmp) / "ds"), cfg],
                             capture_output=True, text=True, check=True).stdout.split()
        return int(out[-1]) / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=24)
    ap.add_argument("--image-size", type=int, default=224)
    args = ap.parse_args()
    cfg = config(args.episodes, args.image_size)
    bound = render_bound(cfg, 1500)
    print(f"render-only bound ({args.image_size} px, 1 core): {bound:,.0f} frames/s")
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        info = generate(Path(tmp) / "ds", cfg, workers=1)
        wall = time.perf_counter() - start
        frames = info["counts"]["frames"]
        size = sum(f["bytes"] for f in info["files"].values())
    fps = frames / wall
    print(f"generate, 1 worker: {args.episodes} episodes, {frames} frames in {wall:.1f} s = {fps:,.0f} frames/s per core")
    print(f"ratio to the render bound: {fps / bound:.2f} (goal >= 0.8)")
    print(f"bytes per frame: {size / frames:,.0f} B ({size / 1e6:.1f} MB for {frames} frames; goal <= 12,000)")
    small, large = max(2, args.episodes // 4), max(6, 3 * (args.episodes // 4))
    m_small, m_large = peak_rss_mb(small, args.image_size), peak_rss_mb(large, args.image_size)
    print(f"peak RSS, 1 worker: {m_small:.0f} MB for {small} episodes, {m_large:.0f} MB for {large} "
          f"(ratio {m_large / m_small:.2f}; flat = 1.0)")


if __name__ == "__main__":
    main()
