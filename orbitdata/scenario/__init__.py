"""Episode specifications: what the world looks like before anyone flies in it."""

from orbitdata.scenario.config import ScenarioConfig
from orbitdata.scenario.geometry import clearance, signed_distance
from orbitdata.scenario.sampler import sample_scenario
from orbitdata.scenario.spec import Lighting, Obstacle, Scenario

__all__ = [
    "Lighting",
    "Obstacle",
    "Scenario",
    "ScenarioConfig",
    "clearance",
    "sample_scenario",
    "signed_distance",
]
