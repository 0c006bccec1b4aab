"""orbitdata: open CubeSat obstacle-avoidance data for latent world models.

The heavy pieces import on first use::

    from orbitdata import load_windows, read_meta   # windowed PyTorch dataset, info + stats (orbitdata.load)
    from orbitdata.sim import CubeSatEnv            # the simulator
    from orbitdata.fly import Pilot, register_pilot # flying, and adding a pilot

The light contract (no MuJoCo, no OMPL): ``orbitdata.schema`` (columns), ``orbitdata.state``
(state layout, rot6d and SO(3) maths), ``orbitdata.codecs`` (frame codecs, stats recipe) and
``orbitdata.info`` (typed meta/info.json).
"""

from orbitdata.lazy import lazy_getattr
from orbitdata.version import __version__

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
