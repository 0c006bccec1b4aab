"""How well do the world model's dynamics, and the same corrected by their misses, predict the
body's turn on the pilot's own flights?

    python benchmarks/check_corrected_flights.py RUN [--pilot oracle-learned-dyn] [--episodes 2] [--seed 0]
        [--fit-steps 1] [--ridges 1e-5] [--fit-frames 40] [--shown 40] [--json OUT]

Flies the dynamic tier's grid (3, 7 and 10 pieces of debris at 1 and 3 m/s, ``--episodes`` per
setting, grid ``--seed``: a validation seed) with ``--set body=corrected``, keeping every frame
the pilots are shown (state, latent) and the thrusts they then command: ``plan.pilot.plan_batch``,
through which every flight plans, is wrapped to keep them (and saved beside ``--json``, so that a
second call with the same ``--json`` scores them again without flying). Then, at every 5th frame t
where the body turns at most 3 rad/s, each model is shown the frames before t (at most
``--shown``; with 40, the one-step correction is fitted to the 31 steps of 5 frames that end in
them, where a flying pilot fits the 40 steps that end in its last 40 frames; 40 plus the
``(history + fit_steps - 1) * 5`` frames a correction's oldest fit reaches back lets every
correction fit 40) and rolls the thrusts flown after t out: the run's world model and probe
(``LearnedDynamics``) and the same corrected (``CorrectedLearnedDynamics``), fitted to each of the
``--fit-steps`` imagined steps with each of the ``--ridges``, over each of the ``--fit-frames``. Their body rate 1, 5, 10 and 25 frames ahead is set against the
flown one (mean absolute error over the 3 axes), beside holding the rate.
``benchmarks/check_fitted_body.py --learned`` scores the same models on the expert's held-out
episodes. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from orbitdata.cli.errors import run_script, script_help
from orbitmodel.cli.app import app
from orbitmodel.kinematics import W
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan import pilot as planning
from orbitmodel.plan.config import PLANNER_PRESETS
from orbitmodel.plan.corrected_body import CorrectedLearnedDynamics
from orbitmodel.plan.dynamics import LearnedDynamics
from orbitmodel.plan.factory import load_planner_probe

AHEAD, EVERY, MAX_RATE = (1, 5, 10, 25), 5, 3.0


def fly(run: str, pilot: str, episodes: int, seed: int, out: Path) -> list[list[tuple]]:
    """The grid's episodes as flown: per episode, each frame's (state (16,), thrusts (8,), latent (D,))."""
    frames: dict[int, list[tuple]] = {}  # per pilot (one per episode flown at a time): its frames
    flown: list[list[tuple]] = []
    shown = planning.plan_batch

    def kept(pilots, observations):
        actions = shown(pilots, observations)
        for p, obs, a in zip(pilots, observations, actions):
            if p._step == 1 and frames.get(id(p)):  # a new episode on this pilot
                flown.append(frames.pop(id(p)))
            frames.setdefault(id(p), []).append((np.asarray(obs["state"]), np.asarray(a), p.dynamics._z[-1].clone()))
        return actions

    planning.plan_batch = kept
    out.with_suffix(".chunks.jsonl").unlink(missing_ok=True)  # every episode flies here, to be seen
    try:
        motion = "true" if pilot != "planner" else "tracker"
        args = ["eval", "closed-loop", run, "--pilot", pilot, "--preset", "cpu", "--config", "configs/dynamic.toml"]
        args += ["--obstacles", "3,7,10", "--speeds", "1,3", "--episodes", str(episodes), "--seed", str(seed)]
        args += ["--threads", "1", "--set", f"obstacle_motion={motion}", "--set", "body=corrected", "--json", str(out)]
        code = app(args, standalone_mode=False)  # an exit code, not an exception, when the flight fails
        if code:
            raise SystemExit(f"error: the flight `orbitmodel {' '.join(map(str, args))}` failed (exit {code})")
    finally:
        planning.plan_batch = shown
    return flown + list(frames.values())


@torch.inference_mode()
def scores(dynamics, flown: list[list[tuple]], shown: int) -> dict:
    """{"frames ahead": rate error, ...} means over the windows, the holding-rate errors and the window count."""
    errors: dict[int, list] = {a: [] for a in AHEAD}
    holding: dict[int, list] = {a: [] for a in AHEAD}
    for episode in flown:
        states = np.stack([f[0] for f in episode]).astype(np.float32)
        actions = np.stack([f[1] for f in episode]).astype(np.float32)
        latents = torch.stack([f[2] for f in episode])
        for t in range(EVERY, len(states) - max(AHEAD), EVERY):
            if np.abs(states[t, W]).max() > MAX_RATE:
                continue
            dynamics.reset()
            first = max(t - shown, 0)
            for j in range(first, t + 1):
                dynamics.push(latents[j], actions[j - 1] if j > first else None, {"state": states[j]})
            plan = torch.from_numpy(actions[t : t + max(AHEAD)])[None]
            out = dynamics.rollout(torch.from_numpy(states[t]), plan)[0].numpy()
            for a in AHEAD:
                errors[a].append(np.abs(out[a - 1, W] - states[t + a, W]).mean())
                holding[a].append(np.abs(states[t, W] - states[t + a, W]).mean())
    return {
        "windows": len(errors[AHEAD[0]]),
        "rate_mae": {a: float(np.mean(v)) for a, v in errors.items()},
        "holding_rate_mae": {a: float(np.mean(v)) for a, v in holding.items()},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("run", help="a run trained on the dynamic tier")
    ap.add_argument("--pilot", default="oracle-learned-dyn", choices=["oracle-learned-dyn", "planner"])
    ap.add_argument("--episodes", type=int, default=2, help="episodes per setting")
    ap.add_argument("--seed", type=int, default=0, help="the grid seed: a validation seed")
    ap.add_argument("--fit-steps", type=int, nargs="+", default=[1], help="the corrections' imagined steps fitted")
    ap.add_argument("--ridges", type=float, nargs="+", default=[1e-5], help="the corrections' ridges")
    ap.add_argument("--fit-frames", type=int, nargs="+", default=[40], help="the corrections' fitted frames")
    ap.add_argument("--shown", type=int, default=40, help="the most frames before each window a model is shown")
    ap.add_argument("--json", type=Path, help="write the figures here (the flight's grid JSON goes beside it)")
    args = ap.parse_args()
    grid = (args.json or Path("corrected-flights.json")).with_suffix(".grid.json")
    kept = grid.with_suffix(".frames.pt")
    flight = {"run": str(Path(args.run).resolve()), "pilot": args.pilot, "episodes": args.episodes, "seed": args.seed}
    cached = torch.load(kept, weights_only=False) if kept.exists() else None
    if isinstance(cached, dict) and cached.get("flight") == flight and cached.get("frames"):
        flown = cached["frames"]  # the same flight, kept from a previous call
    else:
        flown = fly(args.run, args.pilot, args.episodes, args.seed, grid)
        torch.save({"flight": flight, "frames": flown}, kept)
    torch.set_num_threads(1)
    model = WorldModel.from_pretrained(args.run)
    probe = load_planner_probe(Path(args.run), model.fingerprint)
    history = PLANNER_PRESETS["cpu"]().history
    rows = {"world model": scores(LearnedDynamics(model, probe, history=history), flown, args.shown)}
    for frames in args.fit_frames:
        for n in args.fit_steps:
            for ridge in args.ridges:
                corrected = CorrectedLearnedDynamics(model, probe, frames, ridge, fit_steps=n, history=history)
                name = f"corrected, {frames} frames, ridge {ridge:g}, {n} step{'s' * (n > 1)}"
                rows[name] = scores(corrected, flown, args.shown)
    print(
        f"{len(flown)} episodes flown by {args.pilot} with body=corrected, grid seed {args.seed}, {args.shown} frames shown"
    )
    print(f"body-rate error (rad/s), frames ahead {' '.join(f'{a:>6}' for a in AHEAD)}   (windows)")
    for name, row in rows.items():
        errs = " ".join(f"{row['rate_mae'][a]:6.3f}" for a in AHEAD)
        print(f"{name:>45}  {errs}   ({row['windows']})")
    held = " ".join(f"{rows['world model']['holding_rate_mae'][a]:6.3f}" for a in AHEAD)
    print(f"{'the rate held':>45}  {held}")
    if args.json:
        args.json.write_text(
            json.dumps({"run": args.run, "pilot": args.pilot, "seed": args.seed, "shown": args.shown, **rows}, indent=1)
            + "\n"
        )


if __name__ == "__main__":
    run_script(main)
