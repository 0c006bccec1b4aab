"""Presets name what was trained and flown: a Stage I preset carries its probe recipe (no stage
picks a default by the preset's name), and the planner presets are what the CLI flies."""

import dataclasses
import json

import pytest

from orbitmodel.config import PRESETS, Preset, ProbeRecipe, get_preset
from orbitmodel.plan.config import PLANNER_PRESETS, planner_config


def test_each_preset_carries_its_probe_recipe():
    assert (get_preset("paper").probe.inputs, get_preset("paper").probe.integrator) == ("latent", "upstream")
    assert get_preset("paper").probe == ProbeRecipe()  # upstream's recipe, written once
    cpu = get_preset("cpu").probe
    assert (cpu.inputs, cpu.integrator, cpu.train.weights[-1], cpu.train.epochs) == ("latent+change", "coasting", 100.0, 60)


def test_the_flown_preset_is_the_cpu_preset_stepping_five_frames():
    """cpu-step5 is cpu with 5 frames a step and what its validation episodes chose: SIGReg 0.4, 5 %
    of the train episodes held out, a per-frame probe that reads each step's thrusts, scored on each
    frame's increments too."""
    cpu, flown = get_preset("cpu"), get_preset("cpu-step5")
    assert flown.model == dataclasses.replace(cpu.model, frame_step=5, lambda_sigreg=0.4)
    assert flown.train == dataclasses.replace(cpu.train, val_fraction=0.05)
    assert flown.probe == dataclasses.replace(cpu.probe, inputs="latent+change+thrust", per_frame=True,
                                              train=dataclasses.replace(cpu.probe.train, increment_weight=100.0))


def test_a_custom_preset_keeps_its_recipe_through_the_run_config():
    mine = dataclasses.replace(get_preset("cpu"), name="mine", probe=get_preset("cpu").probe.with_changes(epochs=7))
    back = Preset.from_dict(json.loads(json.dumps(mine.to_dict())))
    assert back == mine and back.probe.train.epochs == 7


def test_a_run_config_from_before_recipes_gets_its_named_presets_recipe():
    legacy = get_preset("cpu").to_dict()
    del legacy["probe"]
    assert Preset.from_dict(legacy).probe == get_preset("cpu").probe


@pytest.mark.parametrize("name", list(PRESETS))
def test_presets_round_trip(name):
    p = get_preset(name)
    assert Preset.from_dict(json.loads(json.dumps(p.to_dict()))) == p


def test_planner_presets_and_their_overrides():
    assert set(PLANNER_PRESETS) == {"paper", "cpu"}
    paper, cpu = planner_config("paper"), planner_config("cpu")
    assert (paper.mppi.samples, paper.mppi.horizon, paper.history) == (256, 50, 0)
    assert (cpu.mppi.samples, cpu.mppi.horizon, cpu.history) == (32, 50, 2)
    changed = planner_config("cpu", samples="64", support="0", compile="true")
    assert (changed.mppi.samples, changed.support, changed.compile, changed.history) == (64, 0, True, 2)
    with pytest.raises(ValueError, match="unknown planner preset 'fast'"):
        planner_config("fast")
    with pytest.raises(ValueError, match="unknown planner option 'bogus'"):
        planner_config("cpu", bogus=1)
