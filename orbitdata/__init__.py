"""orbitdata: open CubeSat obstacle-avoidance data for latent world models.

The heavy pieces import on first use::

    from orbitdata import load_windows, read_meta   # windowed PyTorch dataset, info + stats (orbitdata.load)
    from orbitdata.sim import CubeSatEnv            # the simulator
    from orbitdata.fly import Pilot, register_pilot # flying, and adding a pilot

The light contract (no MuJoCo, no OMPL): ``orbitdata.schema`` (columns), ``orbitdata.state``
(state layout, rot6d and SO(3) maths), ``orbitdata.codecs`` (frame codecs, stats recipe) and
``orbitdata.info`` (typed meta/info.json).
"""

__version__ = "0.1.0"



def lazy_getattr(package: str, exports: dict[str, str]):
    """A module ``__getattr__`` that imports ``exports[name]`` (a module path) when ``name`` is first used.

    Packages whose names pull in heavy libraries (MuJoCo, OMPL, torch) export them through this,
    so that importing the package, or a light module inside it, stays light.
    """

    def __getattr__(name: str):
        if name in exports:
            import importlib

            return getattr(importlib.import_module(exports[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


_LAZY = {
    "load_windows": "orbitdata.load",
    "read_meta": "orbitdata.load",
    "WindowDataset": "orbitdata.load",
    "StreamingWindowDataset": "orbitdata.load",
    "CubeSatEnv": "orbitdata.sim",
    "GenerationConfig": "orbitdata.config",
    "generate": "orbitdata.write.generate",
}
__getattr__ = lazy_getattr(__name__, _LAZY)
__all__ = ["__version__", *_LAZY]
