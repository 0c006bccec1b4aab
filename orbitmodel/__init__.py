"""orbitmodel: Orbit-Planner's latent world model on orbitdata datasets.

``from orbitmodel import WorldModel`` is imported on first use, so ``orbitmodel --help`` stays light.
"""

from __future__ import annotations

__all__ = ["WorldModel", "PhysicsProbe", "get_preset", "PRESETS"]


def __getattr__(name: str):
    if name == "WorldModel":
        from orbitmodel.model.world_model import WorldModel

        return WorldModel
    if name == "PhysicsProbe":
        from orbitmodel.probe import PhysicsProbe

        return PhysicsProbe
    if name in ("get_preset", "PRESETS"):
        from orbitmodel import config

        return getattr(config, name)
    raise AttributeError(f"module 'orbitmodel' has no attribute {name!r}")
