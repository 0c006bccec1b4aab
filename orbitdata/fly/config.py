"""What flying reads: the simulator, the scenario randomisation and the built-in pilots' settings.

:class:`FlightConfig` is the part of a dataset's :class:`~orbitdata.config.GenerationConfig`
that a pilot factory and the evaluation grid need (``GenerationConfig.flight``), so that ``fly``
depends on these sections and not on the dataset's size, split or storage.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from orbitdata.fly.pilots.config import PilotsConfig
from orbitdata.scenario.config import ScenarioConfig
from orbitdata.sim.config import SimConfig


@dataclass(frozen=True)
class FlightConfig:
    """The settings a flight is made with.

    Attributes:
        sim: physics, camera, hardware and the episode's frame limit (:class:`SimConfig`).
        scenario: how episodes are randomised (:class:`ScenarioConfig`).
        pilots: the built-in pilots' settings (:class:`PilotsConfig`).
    """

    sim: SimConfig = field(default_factory=SimConfig)
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    pilots: PilotsConfig = field(default_factory=PilotsConfig)
