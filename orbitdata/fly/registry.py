"""Pilots by name: the built-in levels, pilots registered at run time, and other packages' pilots.

A factory makes a pilot for a run: ``factory(config, **options) -> Pilot``, where ``config`` is
the run's :class:`~orbitdata.fly.config.FlightConfig` (``sim``: camera and CubeSat, ``scenario``,
``pilots``: the built-in pilots' settings; a ``GenerationConfig`` has the same sections) and
``options`` are the factory's own keyword arguments (``orbitdata fly --pilot-option KEY=VALUE``
passes strings). Another package adds its pilots with an entry point in its ``pyproject.toml``::

    [project.entry-points."orbitdata.pilots"]
    planner = "orbitmodel.planner:make_planner"      # a factory as above

Entry points are listed by name without being imported; a factory is loaded when its pilot is
made, so ``orbitdata --help`` stays light.
"""

from __future__ import annotations

import inspect
from importlib import metadata
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from orbitdata.fly.config import FlightConfig
    from orbitdata.fly.pilot import Pilot

ENTRY_POINT_GROUP = "orbitdata.pilots"
PilotFactory = Callable[..., "Pilot"]  # factory(config: FlightConfig, **options) -> Pilot


def _draws(plan_draw, noise_draw) -> dict[str, int]:
    draws = {}
    for name, value in (("plan_draw", plan_draw), ("noise_draw", noise_draw)):
        text = str(value).strip()  # option values arrive as text; "1.5" and "True" are no whole numbers
        if not text.isdecimal():
            raise ValueError(f"--pilot-option {name}={value}: give a whole number >= 0 (0: the episode's own)")
        draws[name] = int(text)
    return draws


def _expert(config: FlightConfig, plan_draw=0, noise_draw=0) -> Pilot:
    """The tier's expert, by ``config.scenario.tier``: static, RRT* + PD; dynamic, MPPI over the
    episode's true dynamics. ``plan_draw`` / ``noise_draw`` k > 0: another plan (RRT* tree or MPPI
    sampling) / thrust noise of the same task."""
    from orbitdata.scenario.config import DYNAMIC

    draws = _draws(plan_draw, noise_draw)
    if config.scenario.tier == DYNAMIC:
        from orbitdata.fly.pilots.dynamic_expert import DynamicExpertPilot

        pilots = config.pilots
        return DynamicExpertPilot(
            pilots.dynamic_expert, config.sim.cubesat, pilots.gains, config.sim.max_steps, **draws
        )
    from orbitdata.fly.pilots.control import Controller
    from orbitdata.fly.pilots.expert import ExpertPilot

    return ExpertPilot(config.pilots.expert, controller=Controller(config.sim.cubesat, config.pilots.gains), **draws)


def _expert_snapshot(config: FlightConfig, plan_draw=0, noise_draw=0) -> Pilot:
    """The static expert on any tier: one RRT* plan around the obstacles as they stand at t = 0."""
    from orbitdata.fly.pilots.control import Controller
    from orbitdata.fly.pilots.snapshot import SnapshotExpertPilot

    controller = Controller(config.sim.cubesat, config.pilots.gains)
    return SnapshotExpertPilot(config.pilots.expert, controller=controller, **_draws(plan_draw, noise_draw))


def _risky(config: FlightConfig) -> Pilot:
    from orbitdata.fly.pilots.control import Controller
    from orbitdata.fly.pilots.risky import RiskyPilot

    return RiskyPilot(config.pilots.risky, controller=Controller(config.sim.cubesat, config.pilots.gains))


def _exploratory(config: FlightConfig) -> Pilot:
    from orbitdata.fly.pilots.control import Controller
    from orbitdata.fly.pilots.exploratory import ExploratoryPilot

    return ExploratoryPilot(config.pilots.exploratory, controller=Controller(config.sim.cubesat, config.pilots.gains))


# The dataset's levels (orbitdata.schema.LEVELS), in that order, then the dynamic tier's weak expert.
_FACTORIES: dict[str, PilotFactory] = {
    "expert": _expert,
    "risky": _risky,
    "exploratory": _exploratory,
    "expert-snapshot": _expert_snapshot,
}


def _entry_points() -> dict[str, metadata.EntryPoint]:
    return {ep.name: ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def register_pilot(name: str, factory: PilotFactory, replace: bool = False) -> None:
    """Make ``make_pilot(name)`` (and ``orbitdata fly --pilot NAME``) use ``factory``."""
    if not name or not name.replace("-", "_").isidentifier():
        raise ValueError(f"pilot name {name!r}: use letters, digits, '_' or '-', e.g. 'planner'")
    if not callable(factory):
        raise TypeError(f"the factory of pilot {name!r} must be callable: factory(config, **options) -> Pilot")
    if name in _FACTORIES and not replace:
        raise ValueError(f"a pilot named {name!r} is already registered; pass replace=True to replace it")
    _FACTORIES[name] = factory


def list_pilots() -> tuple[str, ...]:
    """Every pilot name: built-in, registered, then entry points of installed packages."""
    return (*_FACTORIES, *sorted(set(_entry_points()) - set(_FACTORIES)))


def pilot_factory(name: str) -> PilotFactory:
    """The factory of pilot ``name`` (an entry point is loaded and registered on first use)."""
    if name not in _FACTORIES:
        entry = _entry_points().get(name)
        if entry is None:
            raise ValueError(f"unknown pilot {name!r}; expected one of {', '.join(list_pilots())}")
        factory = entry.load()
        if not callable(factory):
            raise TypeError(f"entry point {entry.value!r} of pilot {name!r} is not a factory(config, **options)")
        _FACTORIES.setdefault(name, factory)  # unless importing it registered the name itself
    return _FACTORIES[name]


def make_pilot(name: str, config: FlightConfig | None = None, **options) -> Pilot:
    """A new pilot ``name`` for a run with ``config`` (default: ``FlightConfig()``)."""
    from orbitdata.fly.config import FlightConfig
    from orbitdata.fly.pilot import Pilot

    factory = pilot_factory(name)
    config = config if config is not None else FlightConfig()
    try:
        inspect.signature(factory).bind(config, **options)
    except TypeError as exc:
        raise TypeError(f"pilot {name!r}: {exc}") from None
    pilot = factory(config, **options)
    if not isinstance(pilot, Pilot):
        raise TypeError(f"the factory of pilot {name!r} returned {type(pilot).__name__}, not an orbitdata.fly.Pilot")
    return pilot
