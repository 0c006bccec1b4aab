"""Fly: pilots, one episode (``rollout``) and the evaluation grid (``grid``).

    from orbitdata.fly import Pilot, Task, register_pilot, make_pilot, fly_episode, fly_grid, FlightConfig

The interface a pilot implements is :class:`Pilot` (``reset(task)``, ``act(obs)``) in
:mod:`orbitdata.fly.pilot`; pilots are made by name through :mod:`orbitdata.fly.registry`.
Names import on first use: the registry and the interface are light, flying loads MuJoCo.
"""

from orbitdata.lazy import lazy_getattr

_LAZY = {  # name -> the module that defines it
    **dict.fromkeys(("Pilot", "Task"), "orbitdata.fly.pilot"),
    **dict.fromkeys(("FlightConfig",), "orbitdata.fly.config"),
    **dict.fromkeys(
        ("ENTRY_POINT_GROUP", "PilotFactory", "list_pilots", "make_pilot", "pilot_factory", "register_pilot"),
        "orbitdata.fly.registry",
    ),
    **dict.fromkeys(("EpisodeResult", "fly_episode"), "orbitdata.fly.rollout"),
    **dict.fromkeys(("CellResult", "fly_grid", "grid_report"), "orbitdata.fly.grid"),
}

__getattr__ = lazy_getattr(__name__, _LAZY)
__all__ = sorted(_LAZY)
