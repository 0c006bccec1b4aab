"""``orbitmodel eval closed-loop`` on the dynamic tier: the grid counts the tier's outcomes and its
rejected debris draws, each episode records what it was dealt, and an oracle must say how the debris moves."""

from __future__ import annotations

import dataclasses

import pytest

from orbitdata.config import GenerationConfig
from orbitdata.scenario.sampler import sample_scenario
from orbitdata.schema import outcomes
from orbitmodel.evaluate.closed_loop import ClosedLoop, ClosedLoopRequest, grid_seeds
from orbitmodel.evaluate.success import pool_seeds
from orbitmodel.plan.config import planner_config
from orbitmodel.plan.pilot import Variant


@pytest.fixture(scope="module")
def request_dynamic() -> ClosedLoopRequest:
    return ClosedLoopRequest(
        variant=Variant("oracle-true"),
        obstacles=(3,),
        speeds=(1.0,),
        episodes=2,
        seed=0,
        settings=planner_config("cpu", obstacle_motion="true"),
        preset="cpu",
        config=GenerationConfig.for_tier("dynamic"),
        max_steps=12,
    )


def test_a_dynamic_grid_counts_the_tiers_outcomes_rejections_and_factors(request_dynamic):
    flight = ClosedLoop(request_dynamic)
    result = flight.fly()
    report = flight.report(result)
    assert report["tier"] == "dynamic"
    (setting,) = report["settings"]
    assert set(outcomes("dynamic")) <= set(setting)
    assert sum(setting[k] for k in outcomes("dynamic")) == setting["episodes"] == 2
    # Every episode's pieces and the draws rejected on the way to them, as its world drawn again from its seed
    config = request_dynamic.config.scenario
    worlds = [sample_scenario(e.seed, config, 3, 1.0) for e in grid_seeds((3,), (1.0,), 2, 0)]
    rejected = sum(w.dynamics.unsurvivable_draws for w in worlds)
    assert report["rejections"]["debris"] == sum(len(w.obstacles) for w in worlds) == 2 * 3
    assert report["rejections"]["unsurvivable_draws"] == rejected
    assert report["rejections"]["rate"] == pytest.approx(rejected / (rejected + 6))
    for episode in result.episodes:
        assert episode["debris"] == 3
        assert episode["fault"] in ("none", "off", "scaled", "stuck")
        assert isinstance(episode["cw"], bool) and isinstance(episode["eclipse"], bool)
        assert episode["fuel_used"] > 0 and episode["delta_v_mps"] > 0  # the oracle thrusts from the first frame


def test_an_oracle_on_moving_debris_must_say_how_it_moves_before_anything_flies(request_dynamic):
    static = dataclasses.replace(request_dynamic, settings=planner_config("cpu"))
    with pytest.raises(ValueError, match="obstacle_motion=true"):
        ClosedLoop(static)


def test_seeds_flown_with_another_obstacle_motion_do_not_pool():
    def report(seed, planner):
        settings = [{"obstacles": 3, "speed": 1.0, "episodes": 1, "success": 1, "collision": 0, "timeout": 0}]
        return {"pilot": "planner", "seed": seed, "planner": planner, "settings": settings}

    with pytest.raises(ValueError, match="obstacle_motion"):
        pool_seeds([report(3, {}), report(4, {"obstacle_motion": "tracker"})])
    # the oracle of the design's body is another pilot
    with pytest.raises(ValueError, match="with body true, seed 3 with nominal"):
        pool_seeds([report(3, {"body": "nominal"}), report(4, {})])
    # nor does a body fitted to another history
    with pytest.raises(ValueError, match="fit_frames 10"):
        pool_seeds([report(3, {"body": "fitted", "fit_frames": 40}), report(4, {"body": "fitted", "fit_frames": 10})])
    pool_seeds([report(3, {"body": "inferred"}), report(4, {"body": "inferred", "fit_frames": 40})])
    assert planner_config("cpu", probe="thrust_probe").probe == ""  # the run's own probe has one spelling
    pool_seeds([report(3, {}), report(4, {})])
