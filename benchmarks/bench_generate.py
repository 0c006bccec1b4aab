"""Generation throughput per core against the render-only bound, bytes per frame, and memory.

    python benchmarks/bench_generate.py [--episodes 24] [--image-size 224]
    python benchmarks/bench_generate.py --tier dynamic [--episodes 40] [--workers 2] [--repeats 2]

1. End to end: `generate` with one worker (one core) -> frames/s, wall time of the whole
   command (planning, flying, rendering, encoding, sharding, stats, card).
2. Render-only bound, measured in the same run on the same frames: every generated frame is
   re-rendered from its recorded pose (no physics, no pilot, no encoding) -> frames/s, and
   the ratio of (1) to it (goal >= 0.8).
3. Bytes per frame of the finished dataset (goal <= 12 KB at 224 px).
4. Peak memory (max RSS) of a one-worker generation of N and 3N episodes in subprocesses:
   it should be flat in the number of episodes.

``--tier dynamic`` measures instead that tier's generation against the static tier's, side by
side in one run: the same episode count, root seed, image size (64 px unless given) and workers,
the whole command each time, the two tiers alternating (static, dynamic, static, ...) for
``--repeats`` rounds so that a change in the machine's load falls on both. It prints episodes
(and frames) per second of each run and of each tier over its runs, and the ratio of the
dynamic tier's episodes per second to the static tier's (goal >= 0.5).
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

from orbitdata.cli.errors import run_script, script_help

os.environ.setdefault("LP_NUM_THREADS", "1")  # one core, like one worker

import numpy as np  # noqa: E402

from orbitdata.config import GenerationConfig  # noqa: E402
from orbitdata.sim import CubeSatEnv  # noqa: E402
from orbitdata.viz import overview_figure  # noqa: E402
from orbitdata.write.generate import generate  # noqa: E402

MEM_SCRIPT = """
import resource, sys, os
os.environ.setdefault("LP_NUM_THREADS", "1")
from orbitdata.config import GenerationConfig
from orbitdata.viz import overview_figure
from orbitdata.write.generate import generate
cfg = GenerationConfig.from_dict(__import__("json").loads(sys.argv[2]))
generate(sys.argv[1], cfg, workers=1, figure=overview_figure)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def config(episodes: int, image_size: int, tier: str = "static") -> GenerationConfig:
    cfg = GenerationConfig.for_tier(tier)
    return cfg.replace(
        dataset={"episodes": episodes, "seed": 123},
        sim={"camera": dataclasses.replace(cfg.sim.camera, image_size=image_size)},
    )


def render_bound(cfg: GenerationConfig, dataset: Path) -> float:
    """Frames/s of re-rendering every frame of ``dataset`` from its recorded state."""
    import mujoco
    import pyarrow.parquet as pq

    from orbitdata import schema as S
    from orbitdata.state import rot6d_to_matrix

    env = CubeSatEnv(cfg.sim, cfg.scenario)
    frames, busy = 0, 0.0
    for path in sorted(dataset.glob("episodes/*.parquet")):
        for ep in pq.read_table(path).to_pylist():
            states = (
                pq.read_table(dataset / ep[S.DATA_FILE], columns=[S.STATE])
                .slice(ep[S.ROW_START], ep[S.LENGTH])
                .column(S.STATE)
                .to_pylist()
            )
            env.reset(seed=ep[S.SEED])
            quat = np.zeros(4)
            for s in np.array(states, dtype=np.float64):
                t0 = time.perf_counter()
                mujoco.mju_mat2Quat(quat, rot6d_to_matrix(s[6:12]).reshape(-1))
                env.data.qpos[0:3], env.data.qpos[3:7] = s[0:3], quat
                mujoco.mj_kinematics(env.model, env.data)
                env._observe()
                busy += time.perf_counter() - t0
                frames += 1
    return frames / busy


def peak_rss_mb(episodes: int, image_size: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        cfg = json.dumps(config(episodes, image_size).to_dict())
        out = subprocess.run(
            [sys.executable, "-c", MEM_SCRIPT, str(Path(tmp) / "ds"), cfg], capture_output=True, text=True, check=True
        ).stdout.split()
        return int(out[-1]) / 1024


def compare_tiers(tier: str, episodes: int, image_size: int, workers: int, repeats: int) -> None:
    """Episodes per second of ``generate`` for the static tier and ``tier``, alternating."""
    runs: dict[str, list[tuple[float, int]]] = {"static": [], tier: []}  # (wall s, frames) per run
    print(f"generate, {episodes} episodes per run, {image_size} px, {workers} workers, seed 123, {repeats} rounds")
    for r in range(repeats):
        for name in runs:
            with tempfile.TemporaryDirectory() as tmp:
                start = time.perf_counter()
                info = generate(
                    Path(tmp) / "ds", config(episodes, image_size, name), workers=workers, figure=overview_figure
                )
                wall = time.perf_counter() - start
            frames = info.counts["frames"]
            runs[name].append((wall, frames))
            print(
                f"  round {r + 1}, {name:>7}: {wall:6.1f} s, {episodes / wall:.3f} episodes/s, "
                f"{frames / wall:,.0f} frames/s ({frames / episodes:.0f} frames per episode)"
            )
    rate = {}
    for name, measured in runs.items():
        wall, frames = sum(w for w, _ in measured), sum(f for _, f in measured)
        rate[name] = len(measured) * episodes / wall
        print(f"{name:>7} tier: {rate[name]:.3f} episodes/s, {frames / wall:,.0f} frames/s over {len(measured)} runs")
    print(f"ratio {tier} / static: {rate[tier] / rate['static']:.2f} episodes per second (goal >= 0.5)")


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("--episodes", type=int, default=None, help="episodes per run (24; 40 with --tier)")
    ap.add_argument("--image-size", type=int, default=None, help="camera px (224; 64 with --tier)")
    ap.add_argument("--tier", choices=["dynamic"], default=None, help="compare this tier's generation to the static")
    ap.add_argument("--workers", type=int, default=2, help="workers of each run (--tier only)")
    ap.add_argument("--repeats", type=int, default=2, help="rounds of static then the tier (--tier only)")
    args = ap.parse_args()
    if args.tier is not None:
        if args.workers < 1 or args.repeats < 1:
            ap.error("--workers and --repeats must be >= 1")
        compare_tiers(args.tier, args.episodes or 40, args.image_size or 64, args.workers, args.repeats)
        return
    args.episodes, args.image_size = args.episodes or 24, args.image_size or 224
    cfg = config(args.episodes, args.image_size)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        info = generate(Path(tmp) / "ds", cfg, workers=1, figure=overview_figure)
        wall = time.perf_counter() - start
        frames = info.counts["frames"]
        size = info.bytes
        bound = render_bound(cfg, Path(tmp) / "ds")
    fps = frames / wall
    print(
        f"generate, 1 worker: {args.episodes} episodes, {frames} frames in {wall:.1f} s = {fps:,.0f} frames/s per core"
    )
    print(f"render-only bound on the same frames ({args.image_size} px, 1 core): {bound:,.0f} frames/s")
    print(f"ratio to the render bound: {fps / bound:.2f} (goal >= 0.8)")
    print(f"bytes per frame: {size / frames:,.0f} B ({size / 1e6:.1f} MB for {frames} frames; goal <= 12,000)")
    small, large = max(2, args.episodes // 4), max(6, 3 * (args.episodes // 4))
    m_small, m_large = peak_rss_mb(small, args.image_size), peak_rss_mb(large, args.image_size)
    print(
        f"peak RSS, 1 worker: {m_small:.0f} MB for {small} episodes, {m_large:.0f} MB for {large} "
        f"(ratio {m_large / m_small:.2f}; flat = 1.0)"
    )


if __name__ == "__main__":
    run_script(main)
