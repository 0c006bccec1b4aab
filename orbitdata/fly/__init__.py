"""Fly: pilots, one episode (``rollout``) and the evaluation grid (``grid``).

    from orbitdata.fly import Pilot, Task, register_pilot, make_pilot, fly_episode, fly_grid

The interface a pilot implements is :class:`Pilot` (``reset(task)``, ``act(obs)``) in
:mod:`orbitdata.fly.pilot`; pilots are made by name through :mod:`orbitdata.fly.registry`.
Names import on first use: the registry and the interface are light, flying loads MuJoCo.
"""

_LAZY = {
    "Pilot": "orbitdata.fly.pilot",
    "Task": "orbitdata.fly.pilot",
    "ENTRY_POINT_GROUP": "orbitdata.fly.registry",
    "PilotFactory": "orbitdata.fly.registry",
    "list_pilots": "orbitdata.fly.registry",
    "make_pilot": "orbitdata.fly.registry",
    "pilot_factory": "orbitdata.fly.registry",
    "register_pilot": "orbitdata.fly.registry",
    "EpisodeResult": "orbitdata.fly.rollout",
    "fly_episode": "orbitdata.fly.rollout",
    "CellResult": "orbitdata.fly.grid",
    "fly_grid": "orbitdata.fly.grid",
    "grid_report": "orbitdata.fly.grid",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'orbitdata.fly' has no attribute {name!r}")


__all__ = sorted(_LAZY)
