"""The simulated world: a CubeSat in MuJoCo, its thrusters, fuel and onboard camera.

Names import on first use, so that ``orbitdata.sim.config`` (the light settings) never loads
MuJoCo::

    from orbitdata.sim import CubeSatEnv, SimConfig
"""

_LAZY = {
    "CameraConfig": "orbitdata.sim.config",
    "CubeSatConfig": "orbitdata.sim.config",
    "SimConfig": "orbitdata.sim.config",
    "CubeSatEnv": "orbitdata.sim.env",
    "validate_action": "orbitdata.sim.env",
    "thruster_layout": "orbitdata.sim.thrusters",
    "wrench_matrix": "orbitdata.sim.thrusters",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'orbitdata.sim' has no attribute {name!r}")


__all__ = sorted(_LAZY)
