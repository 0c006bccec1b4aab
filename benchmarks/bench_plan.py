"""Planning latency of the learned planner (world model + probe + depth head + MPPI) on this CPU.

    python benchmarks/bench_plan.py [--run RUN] [--planner paper|cpu] [--samples K] [--horizon H]
        [--history N] [--threads 1] [--replan-every 1] [--steps 20] [--sweep] [--floor] [--compile]
        [--precision bfloat16] [--probe NAME ...] [--profile]

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
untimed warm-up steps that fill the context. ``--precision bfloat16`` runs the planner's rollout in
bfloat16 (``PlannerConfig.precision``).
``--profile`` adds where the K candidates' rollout spends its time (torch.profiler's op table)
and its arithmetic: the multiply-adds of its matrix products and the time they need at the rate
this CPU reaches on one product of the predictor's MLP shape (an estimate: the op table's share
says what they took; larger products can run faster); and the rollout with the other ways this
CPU offers: a window of two latents through the fused attention kernel or the math one instead of
written out (``orbitmodel.model.vit.causal_window_attention``), torch.compile, int8 dynamic
quantisation of the linear layers and bfloat16 (the last two with their error). It runs without
``--compile`` and ``--sweep``.
``--probe NAME`` (repeatable) also times the planner reading another of the run's probes
(``PlannerConfig.probe``: a Table I variant such as ``thrust_only``, or ``latent_probe``), each
line beside the run's own probe's; without ``--run``, an untrained probe of that variant's recipe.
A probe that reads no latent skips the world model's rollout, so its line has no rollout share.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np
import torch

from orbitdata.cli.errors import run_script, script_help
from orbitdata.fly.pilot import Task
from orbitdata.sim.config import CameraConfig, SimConfig
from orbitmodel.config import PRESETS, get_preset
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.config import PLANNER_PRESETS, PRECISIONS, PROBES, planner_config
from orbitmodel.plan.dynamics import LearnedDynamics
from orbitmodel.plan.factory import PredictedDepth, load_planner_probe, prepare_rollout
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
    config = planner_config(
        args.planner,
        replan_every=replan_every,
        compile=args.compile,
        precision=args.precision,
        probe=probe_name,
        **changes,
    )
    prepare_rollout(model, config)
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


def call_ms(fn, n: int, warmup: int) -> tuple[float, float]:
    """(median, p95) ms of ``n`` calls of ``fn`` after ``warmup`` untimed ones."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times)), 1e3 * float(np.percentile(times, 95))


def sequential_floor(args, horizon: int | None) -> str:
    """Median ms of rolling ONE candidate H steps through the predictor, eager and compiled."""
    pilot, _ = make_pilot(args, 2, horizon, 1)
    horizon = pilot.config.mppi.horizon
    model, history = pilot.dynamics.model, pilot.dynamics.history
    steps = horizon // model.config.frame_step  # predictor calls for H frames
    g = torch.Generator().manual_seed(0)
    z = torch.randn(1, history, model.config.latent_dim, generator=g)
    actions = torch.rand(1, history - 1 + steps, model.config.step_action_dim, generator=g)

    def rollout():
        return model.rollout(z, actions, history=history)

    eager = call_ms(rollout, n=9, warmup=1)[0]
    model.compile_rollout()  # this pilot's own model: the imagined step through torch.compile
    compiled = call_ms(rollout, n=9, warmup=1)[0]
    return (
        f"sequential floor, K=1 H={horizon} ({steps} predictor calls) history {history}: {eager:.1f} ms eager, "
        f"{compiled:.1f} ms with torch.compile ({compiled / steps:.2f} ms per imagined step)"
    )


def rollout_profile(args) -> str:
    """The K-candidate rollout alone: its op table, its matrix products' floor, and other kernels."""
    import copy
    from unittest import mock

    from torch.nn.attention import SDPBackend, sdpa_kernel
    from torch.profiler import ProfilerActivity, profile

    from orbitmodel.model import vit

    pilot, _ = make_pilot(args, args.samples, args.horizon, 1)
    model, history = pilot.dynamics.model, pilot.dynamics.history
    K, horizon = pilot.config.mppi.samples, pilot.config.mppi.horizon
    c = model.config
    steps = horizon // c.frame_step
    g = torch.Generator().manual_seed(0)
    z = torch.randn(K, history, c.latent_dim, generator=g)
    actions = torch.rand(K, history - 1 + steps, c.step_action_dim, generator=g)

    def timed(fn, n: int = 15) -> tuple[float, float]:
        return call_ms(fn, n=n, warmup=3)

    def roll(m=model):
        return m.rollout(z, actions, history=history)

    def kernel_window(qkv: torch.Tensor, last: bool = False) -> torch.Tensor:
        """The window of at most two tokens through the fused kernel (the final block still on its
        last position alone): what writing the window out saves."""
        q, k, v = qkv.permute(2, 0, 3, 1, 4)
        y = torch.nn.functional.scaled_dot_product_attention(q, k, v, is_causal=True).transpose(1, 2)
        return y[:, -1:] if last else y

    lines = [f"rollout alone, K={K} H={horizon} ({steps} predictor calls) history {history}:"]
    eager = timed(roll)
    lines.append(f"  eager                     {eager[0]:7.1f} ms median {eager[1]:7.1f} p95")
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(5):
            roll()
    total = sum(e.self_cpu_time_total for e in prof.key_averages())
    top = sorted(prof.key_averages(), key=lambda e: -e.self_cpu_time_total)[:8]
    lines.append(
        "  ops: "
        + ", ".join(f"{e.key.removeprefix('aten::')} {100 * e.self_cpu_time_total / total:.0f} %" for e in top)
    )
    # multiply-adds of the matrix products: once per rollout, the action encoder and every block's
    # AdaLN modulations on the history - 1 + steps actions; per imagined step, the `history` tokens
    # through every block's qkv, and through its proj and MLP in every block but the last, where the
    # last token alone goes on; then the projector on the last
    rows = K * history
    tokens = K * (history - 1 + steps)
    qkv, rest = 3 * c.latent_dim**2, c.latent_dim**2 + 2 * c.latent_dim * c.pred_mlp
    once = tokens * (c.step_action_dim * c.action_hidden + c.action_hidden * c.latent_dim)
    once += tokens * c.pred_depth * 6 * c.latent_dim**2
    per_step = c.pred_depth * rows * qkv + (c.pred_depth - 1) * rows * rest + K * rest + K * c.latent_dim**2
    macs = once + steps * per_step
    a = torch.randn(rows, c.latent_dim, generator=g)
    w = torch.randn(c.pred_mlp, c.latent_dim, generator=g)
    ms_product = timed(lambda: torch.nn.functional.linear(a, w), n=50)[0]
    rate = 2 * rows * c.latent_dim * c.pred_mlp / (ms_product * 1e-3) / 1e9
    lines.append(
        f"  matrix products: {2 * macs / 1e9:.2f} GFLOP per rollout; this CPU reaches {rate:.0f} GFLOP/s on one "
        f"({rows} x {c.latent_dim}) x ({c.latent_dim} x {c.pred_mlp}) product, so they need about {2 * macs / rate / 1e6:.1f} ms"
    )
    with mock.patch.object(vit, "causal_window_attention", kernel_window):  # no-op beyond 2 tokens
        fused = timed(roll)
        with sdpa_kernel(SDPBackend.MATH):
            math = timed(roll)
    lines.append(f"  fused attention kernel    {fused[0]:7.1f} ms median {fused[1]:7.1f} p95")
    lines.append(f"  math attention kernel     {math[0]:7.1f} ms median {math[1]:7.1f} p95")
    quantised = copy.deepcopy(model)
    with warnings.catch_warnings():  # torch.ao's eager quantisation warns that it moves to torchao
        warnings.simplefilter("ignore")
        quantised.predictor = torch.ao.quantization.quantize_dynamic(
            quantised.predictor, {torch.nn.Linear}, dtype=torch.qint8
        )
    reference = roll()
    error = (roll(quantised) - reference).abs().max().item() / reference.abs().mean().item()
    q = timed(lambda: roll(quantised))
    lines.append(
        f"  int8 dynamic quantisation {q[0]:7.1f} ms median {q[1]:7.1f} p95 (largest error {100 * error:.0f} % of the mean |z|)"
    )
    half = copy.deepcopy(model).bfloat16_rollout()  # what the planner's precision=bfloat16 runs
    error = (roll(half) - reference).abs().max().item()
    b = timed(lambda: roll(half))
    lines.append(
        f"  bfloat16                  {b[0]:7.1f} ms median {b[1]:7.1f} p95 (largest error "
        f"{100 * error / reference.abs().mean().item():.0f} % of the mean |z|)"
    )
    model.compile_rollout()
    compiled = timed(roll)
    lines.append(f"  torch.compile             {compiled[0]:7.1f} ms median {compiled[1]:7.1f} p95")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=script_help(__doc__))
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
        "--precision",
        choices=PRECISIONS,
        default="float32",
        help="what the planner's rollout runs in (PlannerConfig.precision)",
    )
    parser.add_argument(
        "--profile", action="store_true", help="also profile the K candidates' rollout and time other kernels for it"
    )
    parser.add_argument(
        "--probe",
        action="append",
        default=[],
        metavar="NAME",
        help="also time the planner reading this probe of the run (a Table I variant or latent_probe), repeatable",
    )
    args = parser.parse_args()
    if args.profile and (args.compile or args.sweep):
        # --compile would make the profile's eager and copied models run the compiled step
        parser.error(
            f"--profile times the rollout eager and compiled itself: drop --{'compile' if args.compile else 'sweep'}"
        )
    if args.profile and args.precision != "float32":
        parser.error("--profile times the rollout in float32 and in bfloat16 itself: drop --precision")
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
        f"torch {torch.__version__}" + (f", rollout in {args.precision}" if args.precision != "float32" else "")
    )
    with torch.inference_mode():
        if not args.sweep:
            for name in probes:
                print(report(measure(args, args.samples, args.horizon, args.replan_every, name)), flush=True)
            if args.floor:
                print(sequential_floor(args, args.horizon))
            if args.profile:
                print(rollout_profile(args))
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
    run_script(main)
