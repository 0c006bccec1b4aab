"""Planning latency of the learned planner (world model + probe + depth head + MPPI) on this CPU.

    python benchmarks/bench_plan.py [--run RUN] [--planner paper|cpu] [--samples K] [--horizon H]
        [--history N] [--threads 1] [--replan-every 1] [--steps 20] [--sweep] [--floor] [--compile]
        [--probe NAME ...]

Times the ``planner`` pilot's ``act`` on synthetic 64 px frames: per replan and per control
step (median, p95), and the share of the time spent encoding the frame, in the depth head,
rolling the K candidates out through the predictor, in the probe, and in the cost (points and
collision queries included). Goal: <= 40 ms per control step (25 Hz) on 2 cores.

The planner is the ``--planner`` preset (``orbitmodel.plan.config``), with --samples, --horizon
and --history changing single settings. The world model is ``--run``'s (with its probe); without
one, an untrained model and probe of the ``--preset`` sizes (default ``cpu-step5``, the flown
run's): the weights do not change the time.
``--sweep`` prints a table over K, H and the replan interval instead. ``--floor`` adds the
predictor's H sequential steps alone for ONE candidate (K = 1), eagerly and through
``torch.compile`` (needs a C++ compiler): no replan with this predictor and horizon can be
faster, whatever K, so it says whether the 40 ms goal is reachable by sampling fewer candidates.
``--compile`` runs the planner's imagined step through ``torch.compile``; it compiles during the
untimed warm-up steps that fill the context.
``--probe NAME`` (repeatable) also times the planner reading another of the run's probes
(``PlannerConfig.probe``: a Table I variant such as ``thrust_only``, or ``latent_probe``), each
line beside the run's own probe's; without ``--run``, an untrained probe of that variant's recipe.
A probe that reads no latent skips the world model's rollout, so its line has no rollout share.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from orbitdata.fly.pilot import Task
from orbitdata.sim.config import CameraConfig, SimConfig
from orbitmodel.config import PRESETS, get_preset
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import PLANNER_PRESETS, PROBES, planner_config
from orbitmodel.plan.dynamics import LearnedDynamics
from orbitmodel.plan.factory import PredictedDepth, load_planner_probe
from orbitmodel.plan.obstacles import Camera
from orbitmodel.plan.pilot import PlannerPilot, Variant
from orbitmodel.plan.timing import Timings
from orbitmodel.probe import PhysicsProbe
from orbitmodel.probe.train import probe_config
from orbitmodel.probe.variants import FLOWN, LATENT, variant_recipe


def make_pilot(
    args, samples: int | None, horizon: int | None, replan_every: int, probe_name: str = ""
) -> tuple[PlannerPilot, Timings]:
    if args.run:
        model = WorldModel.from_pretrained(args.run)
        probe = load_planner_probe(args.run, model.fingerprint, probe_name)
    else:
        preset = get_preset(args.preset)
        torch.manual_seed(0)
        model = WorldModel(preset.model).eval()
        recipe = variant_recipe(preset.probe, probe_name or FLOWN)
        probe = PhysicsProbe(probe_config(recipe, "latent", preset.model.latent_dim, preset.model.frame_step))
    timings = Timings()
    sim = SimConfig(camera=CameraConfig(image_size=model.config.image_size))
    changes = {k: v for k, v in dict(samples=samples, horizon=horizon, history=args.history).items() if v is not None}
    config = planner_config(args.planner, replan_every=replan_every, compile=args.compile, probe=probe_name, **changes)
    if args.compile:
        model.compile_rollout()
    dynamics = LearnedDynamics(model, probe.eval(), timings, history=config.history or None)
    pilot = PlannerPilot(
        Variant.PLANNER,
        dynamics,
        PredictedDepth(model, timings, frames=dynamics.frames),
        Camera.from_sim(sim),
        config,
        sim,
        timings,
    )
    return pilot, timings


def synthetic_observation(rng: np.random.Generator, t: int, size: int) -> dict:
    """A plausible frame: a random image, a state flying along +x, a depth map with a near blob."""
    depth = np.full((16, 16), 50.1, np.float32)
    depth[5:10, 6:11] = 3.0
    state = np.zeros(16, np.float32)
    state[0], state[3], state[6], state[9], state[15] = 0.04 * t, 1.0, 1.0, 1.0, 1.0
    return {"image": rng.integers(0, 255, (size, size, 3), dtype=np.uint8), "state": state, "depth_low": depth}


def measure(args, samples: int, horizon: int, replan_every: int, probe_name: str = "") -> dict:
    pilot, timings = make_pilot(args, samples, horizon, replan_every, probe_name)
    pilot.reset(Task(goal=(10.0, 0.0, 0.0), goal_radius=0.5, initial_velocity=(1.0, 0.0, 0.0), seed=0))
    rng = np.random.default_rng(0)
    size = pilot.dynamics.model.config.image_size
    dyn = pilot.dynamics  # fill the context first: steady state has a full window
    warm = (dyn.history - 1) * dyn.step + 1
    for t in range(warm):
        pilot.act(synthetic_observation(rng, t, size))
    pilot.step_seconds.clear()
    pilot.replan_seconds.clear()
    timings.clear()
    start = time.perf_counter()
    for t in range(warm, warm + args.steps):
        pilot.act(synthetic_observation(rng, t, size))
    wall = time.perf_counter() - start
    steps, replans = 1e3 * np.array(pilot.step_seconds), 1e3 * np.array(pilot.replan_seconds)
    phases = timings.snapshot()
    return {
        "probe": probe_name or FLOWN,
        "samples": pilot.config.mppi.samples,
        "horizon": pilot.config.mppi.horizon,
        "replan_every": replan_every,
        "history": pilot.dynamics.history,
        "step_median": np.median(steps),
        "step_p95": np.percentile(steps, 95),
        "replan_median": np.median(replans) if len(replans) else float("nan"),
        "replan_p95": np.percentile(replans, 95) if len(replans) else float("nan"),
        "share": {k: v / wall for k, v in sorted(phases.items())},
        "wall": wall,
    }


def report(m: dict) -> str:
    shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in m["share"].items())
    return (
        f"probe {m['probe']:14s} K={m['samples']:4d} H={m['horizon']:3d} history {m['history']} replan every {m['replan_every']}: per control step "
        f"{m['step_median']:7.1f} ms median {m['step_p95']:7.1f} p95; per replan {m['replan_median']:7.1f} / "
        f"{m['replan_p95']:7.1f} ms   [{shares}]"
    )


def sequential_floor(args, horizon: int | None) -> str:
    """Median ms of rolling ONE candidate H steps through the predictor, eager and compiled."""
    pilot, _ = make_pilot(args, 2, horizon, 1)
    horizon = pilot.config.mppi.horizon
    model, history = pilot.dynamics.model, pilot.dynamics.history
    steps = horizon // model.config.frame_step  # predictor calls for H frames
    g = torch.Generator().manual_seed(0)
    z = torch.randn(1, history, model.config.latent_dim, generator=g)
    actions = torch.rand(1, history - 1 + steps, model.config.step_action_dim, generator=g)

    def step(window, mods):  # one imagined step: the predictor on the window, the last frame's change
        return window[:, -1] + model.pred_projector(model.predictor(window, None, mods)[:, -1])

    def rollout(step_fn):
        mods = model.predictor.modulations(model.action_encoder(model._norm_action(actions)))
        zs = list(z.unbind(1))
        for i in range(steps):
            end = history + i
            start = max(0, end - history)
            zs.append(step_fn(torch.stack(zs[start:end], 1), [m[:, start:end] for m in mods]))
        return torch.stack(zs[history:], 1)

    def median_ms(fn, n: int = 9) -> float:
        fn()
        times = []
        for _ in range(n):
            t = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t)
        return 1e3 * float(np.median(times))

    eager = median_ms(lambda: rollout(step))
    compiled_step = torch.compile(step, dynamic=False)
    compiled = median_ms(lambda: rollout(compiled_step))
    return (
        f"sequential floor, K=1 H={horizon} ({steps} predictor calls) history {history}: {eager:.1f} ms eager, "
        f"{compiled:.1f} ms with torch.compile ({compiled / steps:.2f} ms per imagined step)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planner", choices=list(PLANNER_PRESETS), default="paper", help="planner preset")
    parser.add_argument("--samples", type=int, default=None, help="MPPI samples K (default: the preset's)")
    parser.add_argument("--horizon", type=int, default=None, help="MPPI horizon H in frames (default: the preset's)")
    parser.add_argument("--replan-every", type=int, default=1)
    parser.add_argument("--steps", type=int, default=20, help="control steps timed (after the context fills)")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument("--history", type=int, default=None, help="latents per imagined step (default: the preset's)")
    parser.add_argument("--run", default=None, help="a trained run with its probe (default: an untrained --preset)")
    parser.add_argument("--preset", choices=list(PRESETS), default="cpu-step5", help="world-model sizes without --run")
    parser.add_argument("--sweep", action="store_true", help="a table over K, H and the replan interval")
    parser.add_argument("--floor", action="store_true", help="also time one candidate's H sequential steps")
    parser.add_argument(
        "--compile", action="store_true", help="torch.compile the imagined step (WorldModel.compile_rollout)"
    )
    parser.add_argument(
        "--probe",
        action="append",
        default=[],
        metavar="NAME",
        help="also time the planner reading this probe of the run (a Table I variant or latent_probe), repeatable",
    )
    args = parser.parse_args()
    unknown = [p for p in args.probe if p not in PROBES]
    if unknown:
        parser.error(f"--probe {unknown[0]}: choose {LATENT} or a probe variant ({', '.join(PROBES[2:])})")
    if LATENT in args.probe and not args.run:
        parser.error(f"--probe {LATENT}: the choice is a trained run's (RUN/latent_probe.json); give --run RUN")
    probes = ["", *(p for p in args.probe if p not in ("", FLOWN))]  # the run's own first, then each asked
    torch.set_num_threads(args.threads)
    model = args.run or f"untrained {args.preset} preset"
    print(
        f"{model}, planner {args.planner}, {args.threads} torch thread(s), {os.cpu_count()} cores visible, "
        f"torch {torch.__version__}"
    )
    with torch.inference_mode():
        if not args.sweep:
            for name in probes:
                print(report(measure(args, args.samples, args.horizon, args.replan_every, name)), flush=True)
            if args.floor:
                print(sequential_floor(args, args.horizon))
            return
        for samples, horizon, every in [
            (256, 50, 1),
            (128, 50, 1),
            (64, 50, 1),
            (64, 25, 1),
            (32, 25, 1),
            (256, 50, 5),
            (64, 25, 5),
        ]:
            for name in probes:
                print(report(measure(args, samples, horizon, every, name)), flush=True)


if __name__ == "__main__":
    main()
