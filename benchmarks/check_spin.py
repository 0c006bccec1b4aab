"""How often the fault-blind pilots spin the dynamic tier's body up, and why the tier ends such a
flight ``tumbling`` at ``DynamicConfig.max_body_rate``.

    python benchmarks/check_spin.py [--episodes 1000] [--levels risky,exploratory]

1. MuJoCo's Euler step on a torque-free spinning body with an anisotropic inertia (the drawn
   body's kind; the static body's is isotropic): the drift of its angular momentum over 1 s at
   several rates. It grows with the rate until MuJoCo declares the state unstable and resets it.
2. The risky and exploratory pilots on the first ``--episodes`` seeds of the dynamic tier, no
   rendering: outcomes (``tumbling`` included), the flights MuJoCo reset (the env raises
   ``SimulationUnstable``) and the body's peak rate. Faults of the tumbling flights by kind.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import mujoco
import numpy as np

from orbitdata.cli.errors import run_script, script_help
from orbitdata.fly.registry import make_pilot
from orbitdata.fly.rollout import fly_episode
from orbitdata.scenario.config import ScenarioConfig
from orbitdata.schema import TUMBLING
from orbitdata.sim import CubeSatEnv, SimConfig
from orbitdata.sim.env import SimulationUnstable
from orbitdata.state import ANGULAR_VELOCITY

SPINNING_BODY = """<mujoco><option timestep="{timestep}" gravity="0 0 0"/><worldbody><body name="b"><freejoint/>
<inertial pos="0 0 0" mass="1.3" diaginertia="0.0015 0.0019 0.0021"/></body></worldbody></mujoco>"""


def momentum_drift(rate: float, timestep: float, seconds: float = 1.0) -> float:
    """Relative change of |L| of a torque-free body spun at ``rate`` rad/s after ``seconds``."""
    model = mujoco.MjModel.from_xml_string(SPINNING_BODY.format(timestep=timestep))
    data = mujoco.MjData(model)
    axis = np.array([1.0, 0.3, 0.2]) / np.linalg.norm([1.0, 0.3, 0.2])
    data.qvel[3:6] = rate * axis
    mujoco.mj_forward(model, data)
    inertia = model.body_inertia[1]

    def momentum() -> float:
        return float(np.linalg.norm(data.xmat[1].reshape(3, 3) @ (inertia * data.qvel[3:6])))

    before = momentum()
    for _ in range(round(seconds / timestep)):
        mujoco.mj_step(model, data)
    return momentum() / before - 1.0


def fly_level(level: str, episodes: int) -> None:
    config = ScenarioConfig.for_tier("dynamic")
    env = CubeSatEnv(SimConfig(render=False), config)
    pilot = make_pilot(level)
    outcomes, faults, peaks, resets = Counter(), Counter(), [], []
    start = time.perf_counter()
    for seed in range(episodes):
        try:
            result = fly_episode(env, pilot, seed)
        except SimulationUnstable:
            resets.append(seed)
            continue
        outcomes[result.outcome] += 1
        peaks.append(float(np.linalg.norm(result.states[:, ANGULAR_VELOCITY], axis=1).max()))
        if result.outcome == TUMBLING:
            faults[result.scenario.dynamics.fault.kind] += 1
    p = np.array(peaks)
    print(f"{level}, seeds 0..{episodes - 1} ({time.perf_counter() - start:.0f} s): {dict(sorted(outcomes.items()))}")
    print(f"  flights MuJoCo reset (SimulationUnstable): {len(resets)} {resets[:10]}")
    print(f"  tumbling by fault: {dict(sorted(faults.items()))}")
    print(
        f"  peak body rate, rad/s: median {np.median(p):.1f}, p99 {np.percentile(p, 99):.1f}, max {p.max():.1f}; "
        f"above 20: {(p > 20).sum()}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=script_help(__doc__))
    ap.add_argument("--episodes", type=int, default=1000, help="seeds 0..N-1 of the dynamic tier per level")
    ap.add_argument("--levels", default="risky,exploratory")
    args = ap.parse_args()
    timestep = SimConfig().dt / SimConfig().substeps
    print(f"torque-free spin, MuJoCo Euler, timestep {timestep * 1e3:g} ms: drift of |L| over 1 s")
    for rate in (6.3, 10.0, 20.0, 35.0, 50.0, 100.0):
        print(f"  {rate:5.1f} rad/s: {100 * momentum_drift(rate, timestep):+.2f} %")
    for level in args.levels.split(","):
        fly_level(level.strip(), args.episodes)


if __name__ == "__main__":
    run_script(main)
