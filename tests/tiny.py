"""Settings for the tiny datasets tests generate (64 px, a handful of episodes)."""

from __future__ import annotations


def tiny_config(episodes: int = 6, seed: int = 0, **dataset):
    from orbitdata.config import GenerationConfig

    cfg = GenerationConfig()
    return cfg.replace(
        dataset={
            "episodes": episodes,
            "seed": seed,
            "test_fraction": 0.34,
            "episodes_per_unit": 2,
            "row_group_rows": 64,
            **dataset,
        },
        sim={"camera": cfg.sim.camera.__class__(image_size=64)},
    )


def dynamic_config(episodes: int = 6, seed: int = 0, **dataset):
    """A tiny dataset of the dynamic tier: 32 px, otherwise as :func:`tiny_config`."""
    import dataclasses

    from orbitdata.scenario.config import ScenarioConfig

    cfg = tiny_config(episodes, seed, **dataset)
    cfg = dataclasses.replace(cfg, scenario=ScenarioConfig.for_tier("dynamic"))
    return cfg.replace(sim={"camera": cfg.sim.camera.__class__(image_size=32)})
