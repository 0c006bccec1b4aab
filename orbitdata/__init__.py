"""orbitdata: open CubeSat obstacle-avoidance data for latent world models.

The heavy pieces import on first use::

    from orbitdata import load_windows      # windowed PyTorch dataset (orbitdata.load)
    from orbitdata.sim import CubeSatEnv    # the simulator
"""

__version__ = "0.1.0"

_LAZY = {
    "load_windows": ("orbitdata.load", "load_windows"),
    "WindowDataset": ("orbitdata.load", "WindowDataset"),
    "StreamingWindowDataset": ("orbitdata.load", "StreamingWindowDataset"),
    "CubeSatEnv": ("orbitdata.sim", "CubeSatEnv"),
    "GenerationConfig": ("orbitdata.config", "GenerationConfig"),
    "generate": ("orbitdata.dataset.generate", "generate"),
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'orbitdata' has no attribute {name!r}")


__all__ = ["__version__", *_LAZY]
