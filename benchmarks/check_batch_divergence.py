"""Does a lockstep batch part from the unbatched flight? Thrusts step by step.

    python benchmarks/check_batch_divergence.py RUN [--pilot planner] [--config configs/dynamic.toml]
        [--obstacles 3] [--speed 1] [--episodes 4] [--seed 0] [--frames 12] [--threads 1] [--set KEY=VALUE ...]

Flies the grid's first ``--episodes`` episodes of one setting for ``--frames`` frames each, once
one at a time (``orbitdata.fly.rollout.fly_episode``, the unbatched flight) and once all of them
in one lockstep batch (``orbitmodel.evaluate.lockstep.fly_lockstep``), the planning pilot
``--pilot`` with the planner preset ``cpu`` and the ``--set`` changes, on ``--threads`` torch
threads. Prints, per episode, both outcomes, the first step whose thrusts differ (None: flown bit
for bit), the largest thrust difference at each step, and the largest state difference at the last
common frame, then how many episodes flew identically. A batched call whose sums ran in another order than the lone
call's shows as a difference of about 1e-7 at first; a jump marks a threshold that rounding
crossed (a depth point kept or dropped, a candidate's weight). Asserts nothing.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from orbitdata.cli.errors import run_script, script_help
from orbitdata.cli.options import key_values
from orbitdata.config import GenerationConfig
from orbitdata.fly.rollout import fly_episode
from orbitdata.sim.env import CubeSatEnv
from orbitmodel.evaluate.closed_loop import ClosedLoop, ClosedLoopRequest, pilot_settings
from orbitmodel.evaluate.lockstep import fly_lockstep
from orbitmodel.plan.variant import Variant


def main() -> None:
    parser = argparse.ArgumentParser(description=script_help(__doc__))
    parser.add_argument("run", nargs="?", help="a trained run with its probe and depth refit (none for oracle-true)")
    parser.add_argument("--pilot", default="planner", choices=[v.value for v in Variant], help="the planning pilot")
    parser.add_argument("--config", default="configs/dynamic.toml", help="scenario and simulator settings (TOML)")
    parser.add_argument("--obstacles", type=int, default=3)
    parser.add_argument("--speed", type=float, default=1.0)
    parser.add_argument("--episodes", type=int, default=4, help="episodes, flown alone and then as one batch")
    parser.add_argument("--seed", type=int, default=0, help="grid seed (a validation seed)")
    parser.add_argument("--frames", type=int, default=12, help="frames per episode at most")
    parser.add_argument("--threads", type=int, default=1, help="torch threads for both flights")
    parser.add_argument("--set", dest="set_", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    settings, preset = pilot_settings(args.run, "cpu", **key_values(args.set_, "--set", "samples=32"))
    config = GenerationConfig.from_toml(args.config) if args.config else GenerationConfig()
    req = ClosedLoopRequest(
        run=args.run,
        obstacles=(args.obstacles,),
        speeds=(args.speed,),
        episodes=args.episodes,
        seed=args.seed,
        settings=settings,
        preset=preset,
        config=config,
        max_steps=args.frames,
        variant=Variant(args.pilot),
    )
    loop = ClosedLoop(req)
    env = CubeSatEnv(loop.sim, config.scenario)
    try:
        alone = [fly_episode(env, loop.pilot, s, n, v, image_quality=loop.image_quality) for n, v, _, s in loop.order]
    finally:
        env.close()
    batched: dict[int, object] = {}
    fly_lockstep(
        loop.pilot,
        lambda: CubeSatEnv(loop.sim, config.scenario),
        loop.order,
        len(loop.order),
        lambda i, result, *_: batched.update({i: result}),
        loop.image_quality,
    )
    same = 0
    for i, a in enumerate(alone):
        b = batched[i]
        T = min(len(a.actions), len(b.actions))
        thrust = np.abs(a.actions[:T] - b.actions[:T]).max(axis=1)
        first = int(np.argmax(thrust > 0)) if (thrust > 0).any() else None
        state = float(np.abs(a.states[T - 1] - b.states[T - 1]).max())
        steps = np.array2string(thrust, precision=1, max_line_width=400)
        print(
            f"episode {i}: {a.outcome} / {b.outcome}, {a.length} / {b.length} frames; first differing thrust at "
            f"step {first}; largest thrust difference per step {steps}; largest state difference at frame {T - 1}: {state:.2e}"
        )
        same += first is None and a.length == b.length and np.array_equal(a.states, b.states)
    print(f"{same} of {len(alone)} episodes flown identically alone and in the batch")


if __name__ == "__main__":
    run_script(main)
