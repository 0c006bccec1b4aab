"""Presets name what was trained and flown: a Stage I preset carries its probe recipe (no stage
picks a default by the preset's name), and the planner presets are what the CLI flies."""

import dataclasses
import json

import pytest

from orbitmodel.baselines.diffusion.config import POLICY_PRESETS, PolicyPreset, PolicyTrainConfig, get_policy_preset
from orbitmodel.config import PRESETS, Preset, ProbeRecipe, ProbeTrainConfig, TrainConfig, get_preset
from orbitmodel.plan.config import PLANNER_PRESETS, planner_config, recorded
from orbitmodel.plan.factory import build_pilot
from orbitmodel.plan.pilot import Variant


def test_each_preset_carries_its_probe_recipe():
    assert (get_preset("paper").probe.inputs, get_preset("paper").probe.integrator) == ("latent", "upstream")
    assert get_preset("paper").probe == ProbeRecipe()  # upstream's recipe, written once
    cpu = get_preset("cpu").probe
    assert (cpu.inputs, cpu.integrator, cpu.train.weights[-1], cpu.train.loop.epochs) == (
        "latent+change",
        "coasting",
        100.0,
        60,
    )


def test_the_flown_preset_is_the_cpu_preset_stepping_five_frames():
    """cpu-step5 is cpu with 5 frames a step and what its validation episodes chose: SIGReg 0.4, 5 %
    of the train episodes held out, a per-frame probe that reads each step's thrusts, scored on each
    frame's increments too."""
    cpu, flown = get_preset("cpu"), get_preset("cpu-step5")
    assert flown.model == dataclasses.replace(cpu.model, frame_step=5, lambda_sigreg=0.4)
    assert flown.train == dataclasses.replace(cpu.train, val_fraction=0.05)
    assert flown.probe == dataclasses.replace(
        cpu.probe,
        inputs="latent+change+thrust",
        per_frame=True,
        train=dataclasses.replace(cpu.probe.train, increment_weight=100.0),
    )


def test_the_dynamic_tiers_preset_changes_only_the_probes_context_and_rate():
    """cpu-step5-dynamic is cpu-step5 with a probe that reads 2 steps of context, trained on windows
    at or below 3 rad/s: the same model, the same Stage I, everything else the same."""
    flown, tier = get_preset("cpu-step5"), get_preset("cpu-step5-dynamic")
    assert tier.model == flown.model
    assert tier.train == flown.train
    assert tier.probe == dataclasses.replace(
        flown.probe, train=dataclasses.replace(flown.probe.train, context=2, max_body_rate=3.0)
    )


def test_the_lite_preset_is_the_flown_preset_with_a_one_block_predictor():
    """cpu-step5-lite changes the predictor's depth and nothing else: the same encoder, latent,
    training and probe recipe, so its figures compare with a cpu-step5 run's."""
    flown, lite = get_preset("cpu-step5"), get_preset("cpu-step5-lite")
    assert lite.model == dataclasses.replace(flown.model, pred_depth=1)
    assert (lite.train, lite.probe) == (flown.train, flown.probe)


def test_a_custom_preset_keeps_its_recipe_through_the_run_config():
    mine = dataclasses.replace(get_preset("cpu"), name="mine", probe=get_preset("cpu").probe.with_changes(epochs=7))
    back = Preset.from_dict(json.loads(json.dumps(mine.to_dict())))
    assert back == mine and back.probe.train.loop.epochs == 7


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
    for key, value in (("margin", "nan"), ("collision", "nan"), ("temperature", "inf"), ("noise_std", "-inf")):
        with pytest.raises(ValueError, match=f"planner option {key}='{value}': give a finite number"):
            planner_config("cpu", **{key: value})
    for key in ("max_range", "footprint", "torque_noise"):
        with pytest.raises(ValueError, match=f"{key}=-1.0"):
            planner_config("cpu", **{key: "-1"})
    with pytest.raises(ValueError, match="replan_every=51: a plan holds 50 frames"):
        planner_config("cpu", replan_every="51")
    assert planner_config("cpu", replan_every="50", torque_noise="0").replan_every == 50


def test_the_rollouts_precision_is_recorded_only_when_it_is_not_float32():
    """A bfloat16 flight says so in its result file; a float32 one records what it did before the
    setting existed, so it pools with the grids flown then."""
    assert "precision" not in recorded(planner_config("cpu"))
    assert recorded(planner_config("cpu", precision="bfloat16"))["precision"] == "bfloat16"
    with pytest.raises(ValueError, match="precision='half': use float32 or bfloat16"):
        planner_config("cpu", precision="half")
    with pytest.raises(ValueError, match="precision=bfloat16: pilot oracle-true plans with the rigid-body model"):
        build_pilot(Variant.ORACLE_TRUE, None, planner_config("cpu", precision="bfloat16"))


def flat(train: dict) -> dict:
    """A training config as config.json held it before the ``loop`` field: the loop's settings
    beside the stage's own."""
    return {**{k: v for k, v in train.items() if k != "loop"}, **train["loop"]}


@pytest.mark.parametrize("name", list(PRESETS))
def test_a_flat_stage1_config_from_before_the_loop_field_reads_as_the_nested_one(name):
    nested = json.loads(json.dumps(get_preset(name).to_dict()))
    assert set(nested["train"]["loop"]) >= {"lr", "epochs", "max_steps", "seed"}  # new runs write the nested shape
    old = {
        **nested,
        "train": flat(nested["train"]),
        "probe": {**nested["probe"], "train": flat(nested["probe"]["train"])},
    }
    assert "loop" not in old["train"] and old["train"]["batch_size"] == nested["train"]["loop"]["batch_size"]
    assert Preset.from_dict(old) == Preset.from_dict(nested) == get_preset(name)


@pytest.mark.parametrize("name", list(POLICY_PRESETS))
def test_a_flat_policy_config_from_before_the_loop_field_reads_as_the_nested_one(name):
    nested = json.loads(json.dumps(get_policy_preset(name).to_dict()))
    old = {**nested, "train": flat(nested["train"])}
    assert PolicyPreset.from_dict(old) == PolicyPreset.from_dict(nested) == get_policy_preset(name)


def test_a_config_with_the_loop_settings_in_both_places_is_refused():
    train = get_preset("tiny").train.to_dict()
    with pytest.raises(ValueError, match=r"both under 'loop' and beside it \(epochs\)"):
        TrainConfig.from_dict({**train, "epochs": 3})


@pytest.mark.parametrize(
    "train", [TrainConfig(), ProbeTrainConfig(), PolicyTrainConfig()], ids=lambda t: type(t).__name__
)
def test_flat_names_route_into_the_loop_and_its_checks_hold_for_every_stage(train):
    """``with_train(lr=...)``, ``--lr``: a loop setting by its own name lands in ``loop``, the
    stage's own settings stay its own, and the loop's checks are the same in every stage."""
    changed = train.with_changes(lr=0.5, max_steps=7, seed=None)  # None: an unset CLI option
    assert (changed.loop.lr, changed.loop.max_steps, changed.loop.seed) == (0.5, 7, train.loop.seed)
    assert changed.to_dict()["loop"]["lr"] == 0.5 and "lr" not in changed.to_dict() and not hasattr(changed, "lr")
    assert type(changed).from_dict(json.loads(json.dumps(changed.to_dict()))) == changed
    for bad, message in (
        ({"epochs": 0}, "give epochs >= 1"),
        ({"max_steps": -1}, "max_steps >= 0"),
        ({"warmup": 1.0}, r"warmup=1.0 is a fraction"),
        ({"batch_size": 0}, "batch_size=0"),
    ):
        with pytest.raises(ValueError, match=message):
            train.with_changes(**bad)
    with pytest.raises(TypeError):
        train.with_changes(lrr=0.5)  # a misspelt setting is no silent no-op


def test_stage1_keeps_its_own_batch_check():
    with pytest.raises(ValueError, match="BatchNorm and SIGReg need at least 2 windows"):
        get_preset("tiny").with_train(batch_size=1)
    assert ProbeTrainConfig().with_changes(batch_size=1).loop.batch_size == 1  # the probe has no such need
