"""Fly pilots over the dynamic tier's grid and print success with 95 % Wilson intervals.

    python scripts/fly_dynamic.py --pilots expert,expert-snapshot,risky --episodes 20 --seed 2

The grid is the tier's (obstacles 3, 7, 10 x initial speeds 1, 3 m/s), its episodes those that
``orbitdata fly`` flies (``orbitdata.seeding.grid_seed``): seeds 0, 1 and 2 are validation seeds.
Every pilot flies the same episodes, without rendering unless ``--image-size PX``. ``expert`` is
the tier's (MPPI) expert; ``--set KEY=VALUE`` changes one of its settings (``DynamicExpertConfig``).
The table counts the failures by cause (the debris hit, intercepting or drifting, or the timeout,
with or without the fault begun); ``--failures`` lists each one. ``--static N`` also flies the
static expert on the static tier's grid (obstacles 1, 3, 5 x speeds 1, 2 m/s, N episodes each) in
the same run, for seconds per episode side by side.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from collections import Counter

import numpy as np

from orbitdata.cli.errors import run_script, script_help
from orbitdata.fly import FlightConfig, fly_episode, make_pilot
from orbitdata.fly.pilots.config import DynamicExpertConfig
from orbitdata.fly.pilots.dynamic_expert import DynamicExpertPilot
from orbitdata.scenario.config import ScenarioConfig
from orbitdata.scenario.geometry import signed_distance
from orbitdata.schema import DT, outcomes
from orbitdata.seeding import grid_seed
from orbitdata.sim import CameraConfig, CubeSatEnv, SimConfig
from orbitmodel.evaluate.success import rate_text, wilson


def _numbers(kind):
    return lambda text: [kind(x) for x in text.split(",") if x.strip()]


def _expert_config(settings: list[str]) -> DynamicExpertConfig:
    changes = {}
    for item in settings:
        key, _, value = item.partition("=")
        if not hasattr(DynamicExpertConfig, key):
            raise SystemExit(f"error: --set {item}: no setting {key!r} in DynamicExpertConfig")
        changes[key] = type(getattr(DynamicExpertConfig(), key))(value)
    return dataclasses.replace(DynamicExpertConfig(), **changes)


def _cause(result) -> tuple[str, str]:
    """What ended a failed episode, as (a class for the summary, a line): the debris hit (its index,
    intercepting or drifting) or the outcome, and the fault if it had begun."""
    scn, dyn = result.scenario, result.scenario.dynamics
    t = result.length - 1
    faulty = dyn.fault.active(t - 1)
    fault = (
        f"{dyn.fault.kind} thruster {dyn.fault.thruster} from {dyn.fault.onset_time:.2f} s" if faulty else "no fault"
    )
    if result.outcome != "collision":
        return f"{result.outcome}, {'faulty' if faulty else 'sound'}", f"{result.outcome} at frame {t} ({fault})"
    position = result.states[-1, :3].astype(np.float64)
    obstacles = scn.obstacles_at(t * DT)
    i = int(np.argmin([signed_distance(ob, position) for ob in obstacles]))
    motion = dyn.debris[i]
    kind = "intercepting" if motion.intercept else "drifting"
    speed = float(np.linalg.norm(motion.velocity))
    line = f"collision at frame {t} with debris {i} ({kind}, {obstacles[i].shape}, {speed:.2f} m/s; {fault})"
    return f"collision with {kind} debris, {'faulty' if faulty else 'sound'}", line


def fly(pilot, env, seed: int, obstacles: list[int], speeds: list[float], episodes: int) -> dict:
    cells, failures, causes, elapsed, frames = [], [], Counter(), 0.0, 0
    for n in obstacles:
        for v in speeds:
            counts = Counter()
            for k in range(episodes):
                start = time.perf_counter()
                result = fly_episode(env, pilot, grid_seed(seed, n, v, k), n, v)
                elapsed += time.perf_counter() - start
                frames += result.length
                counts[result.outcome] += 1
                if result.outcome != "success" and result.scenario.dynamics is not None:
                    cause, line = _cause(result)
                    causes[cause] += 1
                    failures.append(f"{n} obstacles, {v:g} m/s, episode {k}: {line}")
            names = outcomes(env.scenario_config.tier)
            cells.append({"obstacles": n, "speed": v, "episodes": episodes, **{o: counts[o] for o in names}})
    total = len(obstacles) * len(speeds) * episodes
    return {
        "settings": cells,
        "causes": dict(sorted(causes.items())),
        "failures": failures,
        "seconds_per_episode": elapsed / total,
        "frames": frames / total,
        "rendering": f", rendered at {env.sim.camera.image_size} px" if env.sim.render else ", no rendering",
    }


def table(name: str, report: dict, failures: bool = False) -> str:
    lines = [
        f"## {name}",
        "",
        "| obstacles | speed m/s | success (95 % Wilson) | collision | timeout |",
        "|---|---|---|---|---|",
    ]
    for c in report["settings"]:
        lines.append(
            f"| {c['obstacles']} | {c['speed']:g} | {rate_text(c['success'], c['episodes'])} "
            f"| {c['collision']} | {c['timeout']} |"
        )
    s, n = sum(c["success"] for c in report["settings"]), sum(c["episodes"] for c in report["settings"])
    collision, timeout = (sum(c[o] for c in report["settings"]) for o in ("collision", "timeout"))
    lines.append(f"| pooled | | {rate_text(s, n)} | {collision} | {timeout} |")
    low = min(wilson(c["success"], c["episodes"])[0] for c in report["settings"])
    lines.append(
        f"\nlowest setting's Wilson low {100 * low:.1f} %; {report['seconds_per_episode']:.3f} s per episode "
        f"({report['frames']:.0f} frames on average{report['rendering']})"
    )
    if report["causes"]:
        lines.append("failures: " + "; ".join(f"{cause} {count}" for cause, count in report["causes"].items()))
    return "\n".join(lines + ([f"- {f}" for f in report["failures"]] if failures else []))


def main() -> None:
    parser = argparse.ArgumentParser(description=script_help(__doc__))
    parser.add_argument("--pilots", default="expert,expert-snapshot,risky", help="comma-separated pilot names")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per setting")
    parser.add_argument("--seed", type=int, default=2, help="root seed of the grid (0, 1, 2: validation)")
    parser.add_argument("--obstacles", type=_numbers(int), default=[3, 7, 10])
    parser.add_argument("--speeds", type=_numbers(float), default=[1.0, 3.0])
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="an expert setting")
    parser.add_argument("--static", type=int, default=0, metavar="N", help="also time the static expert")
    parser.add_argument("--image-size", type=int, default=0, metavar="PX", help="render the camera (0: no rendering)")
    parser.add_argument("--failures", action="store_true", help="list every failed episode and its cause")
    parser.add_argument("--json", default=None, help="write every report here")
    args = parser.parse_args()

    sim = SimConfig(
        render=bool(args.image_size), camera=CameraConfig(image_size=args.image_size or CameraConfig.image_size)
    )
    dynamic = FlightConfig(sim=sim, scenario=ScenarioConfig.for_tier("dynamic"))
    env = CubeSatEnv(sim, dynamic.scenario)
    reports = {}
    for name in args.pilots.split(","):
        if name == "expert":
            config = _expert_config(args.set)
            pilot = DynamicExpertPilot(config, sim.cubesat, dynamic.pilots.gains, sim.max_steps)
        else:
            pilot = make_pilot(name, dynamic)
        reports[name] = fly(pilot, env, args.seed, args.obstacles, args.speeds, args.episodes)
        print(table(f"{name}, dynamic tier, seed {args.seed}", reports[name], args.failures) + "\n", flush=True)
    env.close()
    if args.static:
        static_env = CubeSatEnv(sim, ScenarioConfig())
        report = fly(
            make_pilot("expert", FlightConfig(sim=sim)), static_env, args.seed, [1, 3, 5], [1.0, 2.0], args.static
        )
        static_env.close()
        reports["static expert (static tier)"] = report
        print(table(f"static expert, static tier, seed {args.seed}", report), flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"seed": args.seed, "settings": args.set, "reports": reports}, f, indent=1)


if __name__ == "__main__":
    run_script(main)
