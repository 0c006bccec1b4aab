"""Episode specifications: what the world looks like before anyone flies in it, in either tier
(``static``, the paper's scenes, or ``dynamic``: moving debris, orbit, body, fault, sensing).

Names import on first use, so that ``orbitdata.scenario.config`` (the settings) stays light.
"""

from orbitdata.lazy import lazy_getattr

_LAZY = {  # name -> the module that defines it
    **dict.fromkeys(("DynamicConfig", "ScenarioConfig", "TIERS"), "orbitdata.scenario.config"),
    **dict.fromkeys(
        ("BodyParameters", "DebrisMotion", "Dynamics", "Sensing", "ThrusterFault"), "orbitdata.scenario.dynamics"
    ),
    **dict.fromkeys(("clearance", "signed_distance"), "orbitdata.scenario.geometry"),
    **dict.fromkeys(("sample_scenario",), "orbitdata.scenario.sampler"),
    **dict.fromkeys(("ImpossibleScenario", "Lighting", "Obstacle", "Scenario"), "orbitdata.scenario.spec"),
}

__getattr__ = lazy_getattr(__name__, _LAZY)
__all__ = sorted(_LAZY)
