"""Diffusion Policy costs on this machine: inference latency per action chunk, and the
training step.

    python benchmarks/bench_policy.py [--preset cpu] [--threads 2] [--repeats 50] [--run RUN] [--train-steps 0]

Inference: one ``sample_actions`` call for a single observation pair (encoder + 10 DDIM
U-Net passes, batch 1), the work the pilot does once every 8 control steps; median and p95
over ``--repeats`` calls after warm-up. Weights do not change the cost, so an untrained policy
of the preset is timed unless ``--run`` names a trained one. ``--train-steps N`` also times N
optimiser steps (forward, backward, AdamW, EMA) on a synthetic batch of the preset's size,
i.e. the compute of a training step without data loading.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from orbitdata.cli.errors import run_script, script_help


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("--preset", default="cpu")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--run", default=None, help="a trained policy run folder (default: untrained preset)")
    ap.add_argument("--train-steps", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    from orbitmodel.baselines.diffusion.config import get_policy_preset
    from orbitmodel.baselines.diffusion.policy import DiffusionPolicy

    if args.run:
        policy = DiffusionPolicy.from_pretrained(args.run)
        preset_name = f"run {args.run}"
        train = None
    else:
        preset = get_policy_preset(args.preset)
        torch.manual_seed(0)
        policy = DiffusionPolicy(preset.model).eval()
        preset_name, train = f"preset {args.preset}", preset.train
    c = policy.config
    g = torch.Generator().manual_seed(0)
    images = torch.randint(0, 256, (1, c.n_obs_steps, 3, c.image_size, c.image_size), generator=g, dtype=torch.uint8)
    states = torch.zeros(1, c.n_obs_steps, 16)
    states[..., 6:12] = torch.tensor([1.0, 0, 0, 1, 0, 0])
    goal = torch.tensor([[3.0, 0.5, -0.5]])
    for _ in range(3):
        policy.sample_actions(images, states, goal, g)
    times, cpu = [], []
    for _ in range(args.repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        policy.sample_actions(images, states, goal, g)
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    t = np.array(times) * 1e3
    print(
        f"Diffusion Policy ({preset_name}: {policy.num_parameters() / 1e6:.2f}M params, "
        f"{c.inference_steps} DDIM steps) on {args.threads} threads: one {c.horizon}-action chunk "
        f"median {np.median(t):.1f} ms, p95 {np.percentile(t, 95):.1f} ms over {len(t)} calls; "
        f"{np.median(t) / c.n_action_steps:.1f} ms per control step amortised over {c.n_action_steps} "
        f"(the control period is 40 ms); CPU time per chunk {np.median(cpu) * 1e3:.1f} ms, all threads "
        f"(wall far above CPU / threads means the cores were shared)"
    )

    if args.train_steps and train is not None:
        policy.train()
        B = train.loop.batch_size
        batch = {
            "images": torch.randint(
                0, 256, (B, c.n_obs_steps, 3, c.image_size, c.image_size), generator=g, dtype=torch.uint8
            ),
            "states": states.expand(B, -1, -1).clone(),
            "goal": goal.expand(B, -1).clone(),
            "actions": torch.rand(B, c.horizon, 8, generator=g),
        }
        optimizer = torch.optim.AdamW(policy.net.parameters(), lr=train.loop.lr, betas=train.loop.betas)
        steps = []
        for step in range(1, args.train_steps + 2):
            start = time.perf_counter()
            loss, _ = policy(**batch, generator=torch.Generator().manual_seed(step))
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            policy.ema_update(step, train.ema_power, train.ema_max)
            steps.append(time.perf_counter() - start)
        s = np.median(steps[1:])
        print(
            f"training step (batch {B}, compute only): median {s * 1e3:.0f} ms = {1 / s:.2f} steps/s "
            f"over {args.train_steps} steps"
        )


if __name__ == "__main__":
    run_script(main)
