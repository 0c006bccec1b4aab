"""Simulator speed on this machine: physics, rendering, and step()+render end to end.

    python benchmarks/bench_sim.py [--seconds 3]

Prints physics steps/s (control steps of 0.04 s, 8 substeps each), render frames/s for
RGB+depth at 64/128/224 px, end-to-end step()+render frames/s at 224 px, and the ratio of
end-to-end to render-only (goal >= 0.8: the simulation should cost little beside rendering).
The ratio compares the same frames: the end-to-end run records every pose, and the
render-only run replays them. One core: Mesa's llvmpipe runs one thread, as in generation.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("LP_NUM_THREADS", "1")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from orbitdata.cli.errors import run_script, script_help
from orbitdata.sim import CameraConfig, CubeSatEnv, SimConfig  # noqa: E402


def _rate(fn, seconds: float) -> float:
    fn()  # warm-up
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        fn()
        n += 1
    return n / (time.perf_counter() - start)


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("--seconds", type=float, default=3.0, help="measuring time per figure")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    actions = rng.uniform(0.0, 0.15, size=(4096, 8))

    def stepper(env):
        state = {"i": 0}
        env.reset(seed=0, options={"n_obstacles": 5, "speed": 0.0})

        def step():
            state["i"] += 1
            _, _, term, trunc, _ = env.step(actions[state["i"] % len(actions)])
            if term or trunc:
                env.reset(seed=state["i"], options={"n_obstacles": 5, "speed": 0.0})

        return step

    physics = CubeSatEnv(SimConfig(render=False))
    phys_rate = _rate(stepper(physics), args.seconds)
    print(f"physics: {phys_rate:,.0f} control steps/s ({phys_rate * 8:,.0f} substeps/s)")

    render_rates = {}
    for size in (64, 128, 224):
        env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=size)))
        env.reset(seed=1, options={"n_obstacles": 5})
        render_rates[size] = _rate(lambda: env._observe(), args.seconds)
        print(f"render RGB+depth {size:>3} px: {render_rates[size]:,.0f} frames/s")
        env.close()

    # End to end at 224 px, then render-only on exactly the same poses, scene by scene, in
    # alternation (so load from other processes hits both alike); best of 3 rounds. Resets
    # (model build, GL context) are excluded from both timings.
    env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=224)))
    best_e2e = best_render = 0.0
    for _ in range(3):
        t_e2e = t_render = 0.0
        n = 0
        for seed in range(8):
            env.reset(seed=seed, options={"n_obstacles": 5, "speed": 1.0})
            poses, done = [], False
            while not done and len(poses) < 150:
                t0 = time.perf_counter()
                _, _, term, trunc, _ = env.step(actions[len(poses)])
                t_e2e += time.perf_counter() - t0
                poses.append(env.data.qpos.copy())
                done = term or trunc
            for qpos in poses:
                t0 = time.perf_counter()
                env.data.qpos[:] = qpos
                mujoco.mj_kinematics(env.model, env.data)
                env._observe()
                t_render += time.perf_counter() - t0
            n += len(poses)
        best_e2e, best_render = max(best_e2e, n / t_e2e), max(best_render, n / t_render)
    e2e, render_only = best_e2e, best_render
    print(f"step()+render 224 px: {e2e:,.0f} frames/s; render-only on the same frames: {render_only:,.0f} frames/s")
    print(f"ratio end-to-end / render-only at 224 px: {e2e / render_only:.2f} (goal >= 0.8)")


if __name__ == "__main__":
    run_script(main)
