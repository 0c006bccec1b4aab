"""Benchmark the physics probe as the planner calls it: K rollouts of H steps, batched.

    python benchmarks/bench_probe.py [--k 256] [--horizon 50] [--latent-dim 128] [--repeats 50]
                                     [--threads 0] [--device cpu]

Times ``probe(z_future (K, H, D), state0 (K, 16), z_last (K, D))`` with the default probe (it
reads [z_k, z_k - z_{k-1}] and integrates coasting; the MLP on all K x H steps in one call, then
the integration) under ``torch.no_grad()``, and its two parts alone, on random inputs
(the cost does not depend on the weights' values). D = 128 is the ``cpu`` preset's latent size,
256 the ``paper`` one's. Also times the state-only reference MLP, which must step its
increments one at a time. Each figure: median and 95th percentile over ``--repeats`` calls after
``--warmup``; the machine may be shared, so compare figures taken in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from orbitdata import schema as S
from orbitdata.cli.errors import run_script, script_help
from orbitmodel.probe.baselines import STATE_ACTION_DIM, StateDynamics
from orbitmodel.probe.config import ProbeConfig
from orbitmodel.probe.integrator import integrate
from orbitmodel.probe.model import PhysicsProbe


def random_states(k: int, generator: torch.Generator) -> torch.Tensor:
    """(k, 16) plausible states: unit rot6d, small rates, fuel in [0.5, 1]."""
    s = torch.randn(k, S.STATE_DIM, generator=generator) * 0.3
    q = torch.linalg.qr(torch.randn(k, 3, 3, generator=generator)).Q
    s[:, 6:12] = q[..., :2].flatten(-2)
    s[:, 15] = 0.5 + 0.5 * torch.rand(k, generator=generator)
    return s


def timed(fn, repeats: int, warmup: int) -> tuple[float, float]:
    """(median, p95) in milliseconds."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1e3)
    return float(np.median(times)), float(np.percentile(times, 95))


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("--k", type=int, default=256, help="rollouts (MPPI samples)")
    ap.add_argument("--horizon", type=int, default=50, help="steps of 0.04 s")
    ap.add_argument("--latent-dim", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0 = torch's default)")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    g = torch.Generator().manual_seed(0)
    device = torch.device(args.device)
    K, H, D = args.k, args.horizon, args.latent_dim
    probe = PhysicsProbe(ProbeConfig(latent_dim=D, inputs="latent+change", integrator="coasting")).to(device).eval()
    for p in probe.parameters():  # non-zero output layer: the timing of a trained probe
        torch.nn.init.normal_(p, std=0.02, generator=g)
    state_mlp = StateDynamics(ProbeConfig(kind="state", latent_dim=STATE_ACTION_DIM)).to(device).eval()
    z = torch.randn(K, H, D, generator=g).to(device)  # (K, H, D)
    z_last = torch.randn(K, D, generator=g).to(device)  # (K, D)
    features = torch.cat([z, z - torch.cat([z_last[:, None], z[:, :-1]], 1)], -1)  # (K, H, 2D) what the MLP reads
    state0 = random_states(K, g).to(device)  # (K, 16)
    actions = torch.rand(K, H, S.ACTION_DIM, generator=g).to(device)  # (K, H, 8) thrust in [0, 1]
    inc = torch.randn(K, H, 10, generator=g).to(device) * 1e-2

    def sync(fn):
        def run():
            fn()
            if device.type == "cuda":
                torch.cuda.synchronize()

        return run

    cases = {
        "probe forward + integration": lambda: probe(z, state0, z_last),
        "  MLP only (K*H steps)": lambda: probe.increments(features),
        "  integration only": lambda: integrate(state0, inc, coasting=True),
        "state-only MLP rollout (reference)": lambda: state_mlp(state0, actions),
    }
    print(
        f"K = {K} rollouts x H = {H} steps, latent {D}, device {device}, {torch.get_num_threads()} threads, "
        f"{args.repeats} repeats"
    )
    with torch.no_grad():
        for name, fn in cases.items():
            med, p95 = timed(sync(fn), args.repeats, args.warmup)
            print(f"{name:38s} median {med:8.2f} ms   p95 {p95:8.2f} ms   {K * H / med * 1e3 / 1e6:6.2f} M states/s")


if __name__ == "__main__":
    run_script(main)
