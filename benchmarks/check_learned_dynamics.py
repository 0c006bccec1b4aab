"""Where the learned planner's dynamics go wrong: its rollout path against the truth and the rigid body.

    python benchmarks/check_learned_dynamics.py RUN DATASET [--windows 24] [--history 8 2]

1. On random test windows (8 context latents, horizon 50 frames), the planner's own path (``LearnedDynamics``:
   encode each frame, roll the latents out with the recorded actions, integrate with the probe)
   against the recorded states: position error at h = 1, 10, 25, 50 frames, for each ``--history``
   (a run with ``--frame-step`` s sees every s-th of the (8 - 1) s + 1 context frames).
2. From one test frame, the learned rollout against the rigid-body model the simulator
   integrates, for thrust sequences MPPI proposes but experts rarely fly (coasting, noise
   around coasting, one thruster pair at full): the gap says how far from its data the world
   model can be trusted, and so how much an optimiser can exploit it.
Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from orbitdata import schema as S
from orbitdata.cli.errors import run_script, script_help
from orbitdata.load import load_windows
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.dynamics import LearnedDynamics, RigidBodyDynamics
from orbitmodel.probe import PhysicsProbe


def observed(model, probe, window: dict, history: int, context: int = 8) -> LearnedDynamics:
    dyn = LearnedDynamics(model, probe, history=history)
    for t in range(context):
        obs = {"image": window[S.IMAGE][t].permute(1, 2, 0).numpy(), "state": window[S.STATE][t].numpy()}
        dyn.observe(obs, None if t == 0 else window[S.ACTION][t - 1].numpy())
    return dyn


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("run")
    ap.add_argument("dataset")
    ap.add_argument("--windows", type=int, default=24)
    ap.add_argument("--history", type=int, nargs="+", default=[8, 2])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = WorldModel.from_pretrained(args.run)
    probe = PhysicsProbe.from_pretrained(args.run, world_model=model.fingerprint)
    c = (8 - 1) * model.config.frame_step + 1  # context frames: 8 latents one model step apart
    windows = load_windows(args.dataset, split="test", context=c, horizon=50, columns=[S.IMAGE, S.STATE, S.ACTION])
    chosen = np.random.default_rng(args.seed).choice(len(windows), min(args.windows, len(windows)), replace=False)
    horizons = (1, 10, 25, 50)
    for history in args.history:
        errors = []
        for i in chosen:
            w = windows[int(i)]
            pred = observed(model, probe, w, history, c).rollout(w[S.STATE][c - 1], w[S.ACTION][c - 1 : c + 49][None])[
                0
            ]
            errors.append((pred[:, :3] - w[S.STATE][c : c + 50, :3]).norm(dim=-1))
        e = torch.stack(errors)
        print(
            f"recorded actions, history {history}: position error (m) at h = "
            + ", ".join(f"{h}: {float(e[:, h - 1].mean()):.3f}" for h in horizons)
            + f" ({len(chosen)} test windows)"
        )
    w = windows[int(chosen[0])]
    dyn, rigid = observed(model, probe, w, args.history[-1], c), RigidBodyDynamics()
    g = torch.Generator().manual_seed(args.seed)
    pair = torch.zeros(8)
    pair[:2] = 1.0
    for name, actions in (
        ("coasting (all zero)", torch.zeros(4, 50, 8)),
        ("N(0, 0.15) around coasting", (0.15 * torch.randn(4, 50, 8, generator=g)).clamp(0, 1)),
        ("one thruster pair at full", pair.expand(4, 50, 8).clone()),
    ):
        gap = (
            dyn.rollout(w[S.STATE][c - 1], actions)[..., :3] - rigid.rollout(w[S.STATE][c - 1], actions)[..., :3]
        ).norm(dim=-1)
        print(
            f"{name}: learned vs rigid-body position gap (m) at h = 25: {float(gap[:, 24].mean()):.3f}, "
            f"h = 50: {float(gap[:, 49].mean()):.3f}"
        )


if __name__ == "__main__":
    run_script(main)
