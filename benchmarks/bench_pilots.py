"""Pilot costs: RRT* planning time per episode, and per-step control cost beside rendering.

    python benchmarks/bench_pilots.py [--episodes 50]

Planning: the expert's whole reset (RRT* + shortening + time parametrisation) on scenarios
with 5 obstacles at 2 m/s, and on the dataset's random mix (1-5 obstacles, 0.5-2.5 m/s).
Control: mean time of pilot.act() per step for each level, against one 224 px RGB+depth render.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from orbitdata.cli.errors import run_script, script_help
from orbitdata.fly import Pilot, Task, fly_episode, make_pilot
from orbitdata.scenario import sample_scenario
from orbitdata.sim import CameraConfig, CubeSatEnv, SimConfig


def planning_times(episodes: int, **overrides) -> np.ndarray:
    times = []
    for seed in range(episodes):
        scn = sample_scenario(seed, **overrides)
        pilot = make_pilot("expert")
        task = Task(scn.goal, scn.goal_radius, scn.initial_velocity, seed)
        start = time.perf_counter()
        pilot.reset(task, scenario=scn)
        times.append(time.perf_counter() - start)
    return np.array(times)


class TimedPilot(Pilot):
    def __init__(self, pilot):
        self.pilot, self.name, self.privileged, self.elapsed, self.calls = pilot, pilot.name, pilot.privileged, 0.0, 0

    def reset(self, task, **scenario):
        self.pilot.reset(task, **scenario)

    def act(self, obs):
        start = time.perf_counter()
        a = self.pilot.act(obs)
        self.elapsed += time.perf_counter() - start
        self.calls += 1
        return a

    def metadata(self):
        return self.pilot.metadata()


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("--episodes", type=int, default=50)
    args = ap.parse_args()
    for label, kw in (("5 obstacles, 2 m/s", {"n_obstacles": 5, "speed": 2.0}), ("dataset mix", {})):
        t = planning_times(args.episodes, **kw)
        print(
            f"expert planning ({label}, {len(t)} episodes): median {1e3 * np.median(t):.0f} ms, "
            f"p95 {1e3 * np.percentile(t, 95):.0f} ms, max {1e3 * t.max():.0f} ms"
        )

    env = CubeSatEnv(SimConfig(render=False))
    costs = {}
    for level in ("expert", "risky", "exploratory"):
        timed = TimedPilot(make_pilot(level))
        for seed in range(10):
            fly_episode(env, timed, seed)
        costs[level] = timed.elapsed / timed.calls
    render_env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=224)))
    render_env.reset(seed=1, options={"n_obstacles": 5})
    render_env._observe()
    n, start = 200, time.perf_counter()
    for _ in range(n):
        render_env._observe()
    render = (time.perf_counter() - start) / n
    print(f"render RGB+depth 224 px: {1e3 * render:.2f} ms/frame")
    for level, c in costs.items():
        print(f"{level:>11} act(): {1e3 * c:.3f} ms/step = {c / render:.2f} x render")


if __name__ == "__main__":
    run_script(main)
