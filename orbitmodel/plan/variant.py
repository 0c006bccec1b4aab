"""The planning pilots by name: the planner and the oracles that each swap one of its parts for
the truth (dynamics, obstacles or both). Free of torch, so the CLI lists them without loading it."""

from __future__ import annotations

from enum import Enum


class Variant(str, Enum):
    PLANNER = "planner"
    ORACLE_TRUE = "oracle-true"
    ORACLE_LEARNED_DYN = "oracle-learned-dyn"
    ORACLE_TRUE_DYN_DEPTH = "oracle-true-dyn-depth"
    ORACLE_TRUE_DYN_SENSOR = "oracle-true-dyn-sensor"

    @property
    def learned_dynamics(self) -> bool:
        return self in (Variant.PLANNER, Variant.ORACLE_LEARNED_DYN)

    @property
    def obstacles(self) -> str:
        """'depth-head', 'sensor' (the rendered depth_low) or 'true' (the scenario's)."""
        return {
            Variant.ORACLE_TRUE: "true",
            Variant.ORACLE_LEARNED_DYN: "true",
            Variant.ORACLE_TRUE_DYN_SENSOR: "sensor",
        }.get(self, "depth-head")

    @property
    def privileged(self) -> bool:
        return self.obstacles == "true"

    @property
    def needs_model(self) -> bool:
        return self.learned_dynamics or self.obstacles == "depth-head"
