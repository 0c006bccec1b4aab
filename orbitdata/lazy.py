"""Lazy package attributes: a package names what it exports, and the module is imported on first use."""

from __future__ import annotations

import importlib


def lazy_getattr(package: str, exports: dict[str, str]):
    """A module ``__getattr__`` that imports ``exports[name]`` (a module path) when ``name`` is first used.

    Packages whose names pull in heavy libraries (MuJoCo, OMPL, torch) export them through this,
    so that importing the package, or a light module inside it, stays light.
    """

    def __getattr__(name: str):
        if name in exports:
            return getattr(importlib.import_module(exports[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
