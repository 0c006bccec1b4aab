"""How well does a body fitted to the pilot's history predict the body's turn, and from how much history?

    python benchmarks/check_fitted_body.py RUN DATASET [--frames 10 20 40 80] [--ridge 1e-6 1e-5 1e-4 1e-3] [--inferred] [--learned] [--json OUT]

On the run's validation episodes (the train-split episodes it held out), at every 10th frame t
where the body turns at most 3 rad/s, :class:`~orbitmodel.plan.fitted_body.FittedBodyDynamics`
is shown the frames before t (at most ``frames`` of them, the actions between them) and rolls
the recorded thrusts out for 25 frames; its body rate and velocity there are set against the
recorded ones (mean absolute error over the 3 axes), split by whether the episode has a faulty
thruster. References: the design's body (no history: the fit's prior) and the body rate held
constant. ``--inferred`` scores the fit under RUN/body's learned prior at each ``--frames`` up to the
history it was trained on too (``orbitmodel body``; ``--set body=inferred``). ``--learned`` scores the
run's world model and probe (the planner's dynamics, the history it flies with, shown the encoded
frames) and the same corrected by their misses in the ``--frames`` it is shown (``--set body=corrected``;
a step's misses need the world model's context before it, so 40 frames hold 31 steps of 5 frames). Prints figures; asserts nothing. The flights with the fit are ``--set body=fitted``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from orbitdata.cli.errors import run_script, script_help
from orbitdata.load.episodes import load_episode
from orbitdata.sim.config import SimConfig
from orbitmodel.kinematics import V, W
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import PLANNER_PRESETS
from orbitmodel.plan.corrected_body import CorrectedLearnedDynamics
from orbitmodel.plan.dynamics import LearnedDynamics
from orbitmodel.plan.factory import load_planner_probe
from orbitmodel.plan.fitted_body import FittedBodyDynamics
from orbitmodel.plan.frames import encode_frames
from orbitmodel.plan.inferred_body import InferredBodyDynamics, flown_episodes, load_inference
from orbitmodel.runs import read_run_config

AHEAD, EVERY, MAX_RATE = 25, 10, 3.0
# how each row's "ridge" prints: the design's body, the learned prior, the world model, corrected
LABELS = {None: "design", "inferred": "learned", "world model": "wm", "corrected": "wm+fit"}


@torch.inference_mode()
def encoded(model, dataset: str, episodes: list[int], flown) -> list[torch.Tensor]:
    """Each episode's frames encoded as the planner encodes them: latents (L, D), in ``flown``'s order."""
    out = []
    for e, (states, _, _) in zip(episodes, flown):
        frames = load_episode(Path(dataset), e).rgb()
        z = []
        for lo in range(0, len(frames), 64):
            cls, _ = encode_frames(model, frames[lo : lo + 64])
            z.append(model.latent_from_cls(cls, torch.from_numpy(states[lo : lo + 64])))
        out.append(torch.cat(z))
    return out


def scores(dynamics, flown, frames: int, latents: list[torch.Tensor] | None = None) -> dict:
    """{"fault" / "none": [body-rate error, velocity error, holding-rate error] means, and the window
    count}. ``latents``: each episode's encoded frames (L, D), for dynamics that read the world model's."""
    errors: dict[str, list] = {"fault": [], "none": []}
    for i, (states, actions, faulty) in enumerate(flown):
        for t in range(EVERY // 2, len(states) - AHEAD, EVERY):
            if np.abs(states[t, W]).max() > MAX_RATE:
                continue
            dynamics.reset()
            first = max(t - frames, 0)
            for j in range(first, t + 1):
                before = actions[j - 1] if j > first else None
                if latents is None:
                    dynamics.observe({"state": states[j]}, before)
                else:
                    dynamics.push(latents[i][j], before, {"state": states[j]})
            end = dynamics.rollout(torch.from_numpy(states[t]), torch.from_numpy(actions[t : t + AHEAD])[None])[
                0, -1
            ].numpy()
            truth = states[t + AHEAD]
            errors["fault" if faulty else "none"].append(
                (
                    np.abs(end[W] - truth[W]).mean(),
                    np.abs(end[V] - truth[V]).mean(),
                    np.abs(states[t, W] - truth[W]).mean(),
                )
            )
    return {
        k: {
            "windows": len(v),
            "rate_mae": float(np.mean([x[0] for x in v])),
            "velocity_mae": float(np.mean([x[1] for x in v])),
            "holding_rate_mae": float(np.mean([x[2] for x in v])),
        }
        for k, v in errors.items()
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("run", help="a run trained on the dynamic tier: its held-out validation episodes are scored")
    ap.add_argument("dataset", help="the dynamic-tier dataset the run was trained on")
    ap.add_argument("--frames", type=int, nargs="+", default=[10, 20, 40, 80])
    ap.add_argument("--ridge", type=float, nargs="+", default=[1e-6, 1e-5, 1e-4, 1e-3])
    ap.add_argument("--inferred", action="store_true", help="also the fit under RUN/body's learned prior")
    ap.add_argument(
        "--learned",
        action="store_true",
        help="also the run's world model and probe (the planner's dynamics), and corrected by their misses (body=corrected)",
    )
    ap.add_argument("--json", type=Path, help="write the figures here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    held = read_run_config(args.run).validation.episodes
    flown = list(flown_episodes(args.dataset, sorted(held)).values())
    sim = SimConfig(render=False)
    rows = [{"frames": 0, "ridge": None, **scores(FittedBodyDynamics(sim, frames=1, ridge=1.0), flown, 0)}]
    rows += [
        {"frames": f, "ridge": r, **scores(FittedBodyDynamics(sim, frames=f, ridge=r), flown, f)}
        for f in args.frames
        for r in args.ridge
    ]
    if args.inferred:
        inference, learned = load_inference(args.run)
        rows += [
            {
                "frames": f,
                "ridge": "inferred",
                **scores(InferredBodyDynamics(inference, learned, sim, frames=f), flown, f),
            }
            for f in args.frames
            if f <= learned.frames  # the histories it was trained on
        ]
    if args.learned:
        model = WorldModel.from_pretrained(args.run)
        probe = load_planner_probe(Path(args.run), model.fingerprint)
        latents = encoded(model, args.dataset, sorted(held), flown)
        history = PLANNER_PRESETS["cpu"]().history
        world = LearnedDynamics(model, probe, history=history)
        rows.append(
            {"frames": max(args.frames), "ridge": "world model", **scores(world, flown, max(args.frames), latents)}
        )
        rows += [
            {
                "frames": f,
                "ridge": "corrected",
                **scores(CorrectedLearnedDynamics(model, probe, f, history=history), flown, f, latents),
            }
            for f in args.frames
        ]
    print(f"{len(held)} validation episodes of {args.dataset}; errors {AHEAD} frames ahead (rad/s, m/s)")
    print("frames  ridge   | fault: rate  velocity  (windows) | no fault: rate  velocity  (windows)")
    for row in rows:
        f, n = row["fault"], row["none"]
        ridge = LABELS.get(row["ridge"]) or f"{row['ridge']:.0e}"
        print(
            f"{row['frames']:>6}  {ridge:>6}  | {f['rate_mae']:.3f}  {f['velocity_mae']:.3f}  ({f['windows']})"
            f" | {n['rate_mae']:.3f}  {n['velocity_mae']:.3f}  ({n['windows']})"
        )
    hold = rows[0]
    print(
        f"holding the rate: fault {hold['fault']['holding_rate_mae']:.3f}, no fault {hold['none']['holding_rate_mae']:.3f} rad/s"
    )
    if args.json:
        args.json.write_text(
            json.dumps({"run": str(args.run), "dataset": str(args.dataset), "ahead": AHEAD, "rows": rows}, indent=1)
            + "\n"
        )


if __name__ == "__main__":
    run_script(main)
