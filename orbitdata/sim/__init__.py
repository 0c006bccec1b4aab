"""The simulated world: a CubeSat in MuJoCo, its thrusters, fuel and onboard camera.

Names import on first use, so that ``orbitdata.sim.config`` (the light settings) never loads
MuJoCo::

    from orbitdata.sim import CubeSatEnv, SimConfig
"""

from orbitdata.lazy import lazy_getattr

_LAZY = {  # name -> the module that defines it
    **dict.fromkeys(("CameraConfig", "CubeSatConfig", "SimConfig"), "orbitdata.sim.config"),
    **dict.fromkeys(("CubeSatEnv", "validate_action"), "orbitdata.sim.env"),
    **dict.fromkeys(("DynamicWorld",), "orbitdata.sim.dynamic"),
    **dict.fromkeys(("thruster_layout", "wrench_matrix"), "orbitdata.sim.thrusters"),
}

__getattr__ = lazy_getattr(__name__, _LAZY)
__all__ = sorted(_LAZY)
