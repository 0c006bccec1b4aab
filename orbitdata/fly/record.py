"""One flown episode as a grid's ``--json`` records it: the outcome and how it got there.

``orbitdata fly`` and ``orbitmodel eval closed-loop`` write the same keys, so that any pilot's
grid can be broken down alike (``orbitmodel eval factors``): the frames flown (time to the goal
for a success), the closest approach, the distance left to the goal, the fuel used and the
delta-v it bought, and, on the dynamic tier, what the episode was dealt (debris in motion, the
fault, the CW flag, eclipse).
"""

from __future__ import annotations

import math

import numpy as np

from orbitdata.fly.rollout import EpisodeResult
from orbitdata.sim.config import G0, CubeSatConfig
from orbitdata.state import FUEL, POSITION


def delta_v(cubesat: CubeSatConfig, fuel_start: float, fuel_end: float, mass_scale: float = 1.0) -> float:
    """m/s: the delta-v the thrusters gave while the tank went from ``fuel_start`` to ``fuel_end``
    (ratios of a full tank), by the rocket equation ``isp g0 ln(m0 / m1)``. Exact for the
    simulator, whose propellant flows in proportion to the thrust every thruster gives: it is the
    sum over thrusters of thrust / mass, integrated over the flight (thrust that cancels out
    counts too). ``mass_scale``: the episode's factor on the dry mass (the dynamic tier's draw)."""
    dry = cubesat.dry_mass * mass_scale
    start = dry + cubesat.fuel_mass * float(fuel_start)
    end = dry + cubesat.fuel_mass * float(fuel_end)
    return cubesat.isp * G0 * math.log(start / end)


def dynamic_factors(scenario) -> dict:
    """What a dynamic-tier episode was dealt, for success by factor and the grid's rejection rate
    (nothing for a static episode): the debris pieces and draws rejected on the way to them, how
    many pieces move, the fault and its onset frame, the CW flag and eclipse."""
    dyn = scenario.dynamics
    if dyn is None:
        return {}
    return {
        "debris": len(scenario.obstacles),
        "unsurvivable_draws": int(dyn.unsurvivable_draws),
        "debris_moving": sum(1 for m in dyn.debris if any(m.velocity) or any(m.angular_velocity)),
        "fault": dyn.fault.kind,
        "fault_onset_step": int(dyn.fault.onset_step),
        "cw": bool(dyn.cw),
        "eclipse": bool(dyn.sensing.eclipse),
    }


def episode_summary(result: EpisodeResult, cubesat: CubeSatConfig) -> dict:
    """The outcome, frames, closest approach (m), distance left to the goal (m), fuel used (share
    of a full tank), delta-v (m/s) and the dynamic tier's factors of one flown episode."""
    dyn = result.scenario.dynamics
    fuel = result.states[:, FUEL.start]
    goal = np.asarray(result.scenario.goal)
    return {
        "outcome": result.outcome,
        "frames": int(result.length),
        "min_clearance_m": float(result.min_clearance.min()),
        "goal_distance_m": float(np.linalg.norm(result.states[-1, POSITION] - goal)),
        "fuel_used": float(fuel[0] - fuel[-1]),
        "delta_v_mps": delta_v(cubesat, fuel[0], fuel[-1], dyn.body.mass_scale if dyn is not None else 1.0),
        **dynamic_factors(result.scenario),
    }
