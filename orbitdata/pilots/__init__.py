"""Who flies: the expert (OMPL RRT* + PD tracking), risky and exploratory pilots."""

from __future__ import annotations

from orbitdata.pilots.base import Pilot
from orbitdata.pilots.config import PilotsConfig
from orbitdata.pilots.control import Controller
from orbitdata.sim.config import CubeSatConfig

PILOTS = ("expert", "risky", "exploratory")


def make_pilot(level: str, config: PilotsConfig = PilotsConfig(), cubesat: CubeSatConfig = CubeSatConfig()) -> Pilot:
    """A fresh pilot of ``level`` ('expert', 'risky' or 'exploratory')."""
    from orbitdata.pilots.expert import ExpertPilot
    from orbitdata.pilots.exploratory import ExploratoryPilot
    from orbitdata.pilots.risky import RiskyPilot

    controller = Controller(cubesat, config.gains)
    if level == "expert":
        return ExpertPilot(config.expert, controller=controller)
    if level == "risky":
        return RiskyPilot(config.risky.cruise, controller=controller)
    if level == "exploratory":
        e = config.exploratory
        return ExploratoryPilot(e.cruise, e.accel_sigma, e.alpha_sigma, e.thrust_sigma, e.tau, controller=controller)
    raise ValueError(f"unknown pilot {level!r}; expected one of {', '.join(PILOTS)}")


__all__ = ["PILOTS", "Pilot", "PilotsConfig", "make_pilot"]
