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

_LAZY = {
    "load_windows": ("orbitdata.load", "load_windows"),
    "read_meta": ("orbitdata.load", "read_meta"),
    "WindowDataset": ("orbitdata.load", "WindowDataset"),
    "StreamingWindowDataset": ("orbitdata.load", "StreamingWindowDataset"),
    "CubeSatEnv": ("orbitdata.sim", "CubeSatEnv"),
    "GenerationConfig": ("orbitdata.config", "GenerationConfig"),
    "generate": ("orbitdata.write.generate", "generate"),
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'orbitdata' has no attribute {name!r}")


__all__ = ["__version__", *_LAZY]
