"""Does a dynamics model know which way the logged thrusts turn the body?

    python benchmarks/check_rate_response.py RUN DATASET [--split val] [--windows 53] [--history 2]

On the collision-free windows that ``orbitmodel eval probe`` scores (one per episode of the split,
seeded, 8 context steps), each model rolls out the recorded thrusts from the last context state,
and its change of body rate h frames ahead is set against the recorded change: the cosine between
the two (1: the right direction; 0 or below: the wrong one), the share of windows where it is
positive, the ratio of their sizes and the error. The models: the run's planner dynamics
(``LearnedDynamics``: the encoded frames, the imagined latents, the run's probe) and the design's
rigid body (nominal mass, centred, fault-free) that Table I's physics row integrates. A planner
damps a spin only as well as this direction is right. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from check_learned_dynamics import observed  # the planner's dynamics shown a window's context (this folder)

from orbitdata import schema as S
from orbitdata.cli.errors import run_script, script_help
from orbitdata.load import load_windows, read_meta
from orbitmodel.data import split_selection
from orbitmodel.kinematics import W
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.dynamics import RigidBodyDynamics
from orbitmodel.probe import PhysicsProbe
from orbitmodel.probe.evaluate import select_windows


def learned_rollout(model, probe, window: dict, history: int, context: int, horizon: int) -> torch.Tensor:
    """(horizon, 16): the planner's dynamics, shown the context frames, fed the recorded thrusts."""
    actions = window[S.ACTION][context - 1 : context - 1 + horizon][None]
    return observed(model, probe, window, history, context).rollout(window[S.STATE][context - 1], actions)[0]


def summary(pred: torch.Tensor, true: torch.Tensor) -> str:
    """pred, true (N, 3): changes of body rate, rad/s."""
    cos = torch.nn.functional.cosine_similarity(pred, true, dim=-1)
    size = pred.norm(dim=-1) / true.norm(dim=-1).clamp_min(1e-9)
    err = (pred - true).norm(dim=-1)
    return (
        f"cosine median {float(cos.median()):+.2f}, positive in {float((cos > 0).float().mean()):.0%}; "
        f"size ratio median {float(size.median()):.2f}; error {float(err.mean()):.3f} rad/s"
    )


def with_fault(dataset: str, split: str, episodes: np.ndarray) -> torch.Tensor | None:
    """(N,) whether each of these episodes has a faulty thruster; None for a dataset without faults."""
    from orbitdata.load.tables import load_episode_table

    table = load_episode_table(dataset, split, {})
    if "fault" not in table.column_names:
        return None
    kind = {
        int(e): f["kind"] for e, f in zip(table.column(S.EPISODE_INDEX).to_pylist(), table.column("fault").to_pylist())
    }
    return torch.tensor([kind[int(e)] != "none" for e in episodes])


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("run")
    ap.add_argument("dataset")
    ap.add_argument("--split", default="val", choices=("val", "test"))
    ap.add_argument("--windows", type=int, default=53)
    ap.add_argument("--history", type=int, default=2)
    ap.add_argument("--frames", type=int, nargs="+", default=[5, 25])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = WorldModel.from_pretrained(args.run)
    probe = PhysicsProbe.from_pretrained(args.run, world_model=model.fingerprint)
    s = model.config.frame_step
    # the windows eval probe scores: 8 context steps and its longest horizon, 50 frames
    context, horizon = (8 - 1) * s + 1, 50
    if max(args.frames) > horizon:
        raise SystemExit(f"--frames {max(args.frames)}: the windows hold {horizon} frames after the context")
    split, episodes = split_selection(args.split, model.run.validation)
    chosen, _ = select_windows(args.dataset, context, horizon, args.windows, args.seed, split, episodes)
    windows = load_windows(
        args.dataset, split=split, context=context, horizon=horizon, stride=1, episodes=episodes,
        columns=[S.IMAGE, S.STATE, S.ACTION],
    )  # fmt: skip
    sim = read_meta(args.dataset)[0].generation_config().sim
    rigid = RigidBodyDynamics(sim, substeps=sim.substeps)
    true, learned, nominal = [], [], []
    for i in chosen:
        w = windows[int(i)]
        w0 = w[S.STATE][context - 1, W]
        true.append(w[S.STATE][context : context + horizon, W] - w0)
        learned.append(learned_rollout(model, probe, w, args.history, context, horizon)[:, W] - w0)
        actions = w[S.ACTION][context - 1 : context - 1 + horizon][None]
        nominal.append(rigid.rollout(w[S.STATE][context - 1][None], actions)[0, :, W] - w0)
    true, learned, nominal = (torch.stack(x).double() for x in (true, learned, nominal))
    last = max(args.frames)
    print(
        f"{len(chosen)} {args.split} windows of {args.dataset}; {args.run} at history {args.history}; "
        f"recorded change of body rate: median {float(true[:, last - 1].norm(dim=-1).median()):.2f} rad/s "
        f"at {last} frames"
    )
    faulty = with_fault(args.dataset, split, windows.index.episode[np.asarray(chosen)])
    for h in args.frames:
        print(f"h = {h} frames: learned  {summary(learned[:, h - 1], true[:, h - 1])}")
        print(f"h = {h} frames: rigid    {summary(nominal[:, h - 1], true[:, h - 1])}")
        if faulty is not None:
            for name, rows in (("with a fault", faulty), ("without", ~faulty)):
                print(
                    f"  learned, {int(rows.sum())} windows {name}: {summary(learned[rows, h - 1], true[rows, h - 1])}"
                )
    print(f"holding the rate: error {float(true[:, last - 1].norm(dim=-1).mean()):.3f} rad/s at {last} frames")


if __name__ == "__main__":
    run_script(main)
