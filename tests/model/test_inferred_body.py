"""The inferred body: a prior over bodies learned from episodes, under which the pilot's short
history identifies its body better than the least-squares fit alone; the planner flies it from RUN/body."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from orbitdata.sim import SimConfig
from orbitmodel.cli.app import app
from orbitmodel.plan.config import planner_config, recorded
from orbitmodel.plan.factory import build_pilot
from orbitmodel.plan.fitted_body import FittedBodyDynamics, FittedBodyLearnedDynamics, nominal_response
from orbitmodel.plan.inferred_body import (
    Cuts,
    InferenceConfig,
    InferredBodyDynamics,
    flown_episodes,
    load_inference,
    save_inference,
    train_inference,
)
from orbitmodel.publish.files import run_files
from orbitmodel.runs import RunError

SIM = SimConfig(render=False)
LENGTH = 60


def one_off_episode(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A body whose every frame change is exactly X @ B: the design's body with one random
    thruster dead, held at its attitude (so the body-frame changes are the state's)."""
    B = nominal_response(SIM, 1.0)
    dead = int(rng.integers(8))
    B[dead] = 0.0
    actions = rng.uniform(0.0, 0.5, (LENGTH, 8)).astype(np.float32)
    X = np.concatenate([actions, np.ones((LENGTH, 1), np.float32)], 1)
    changes = X @ B.numpy()
    states = np.zeros((LENGTH + 1, 16), np.float32)
    states[:, 6], states[:, 9], states[:, 15] = 1.0, 1.0, 1.0  # identity attitude (6D), a full tank
    states[1:, 3:6] = np.cumsum(changes[:, :3], 0)
    states[1:, 12:15] = np.cumsum(changes[:, 3:], 0)
    return states, np.concatenate([actions, np.zeros((1, 8), np.float32)]), B, dead


@pytest.fixture(scope="module")
def trained():
    rng = np.random.default_rng(0)
    config = InferenceConfig(ahead=10, max_rate=1e9, width=64, steps=300, batch=256)
    train = Cuts([one_off_episode(rng)[:2] for _ in range(150)], SIM, config)
    held = Cuts([one_off_episode(rng)[:2] for _ in range(30)], SIM, config)
    model, card = train_inference(train, held, config, log=lambda _: None)
    return model, config, card


def test_the_learned_prior_predicts_held_out_bodies_better_than_the_fit_alone(trained):
    _, _, card = trained
    assert card["inferred_error"] < 0.75 * card["ridge_error"], card


def test_from_two_frames_it_knows_more_than_the_fit_and_from_forty_it_finds_the_dead_thruster(trained):
    model, config, _ = trained
    states, actions, B, dead = one_off_episode(np.random.default_rng(7))
    inferred = InferredBodyDynamics(model, config, SIM)
    fitted = FittedBodyDynamics(SIM, frames=config.frames, ridge=config.ridge)
    errors = {}
    for name, dyn in (("inferred", inferred), ("fitted", fitted)):
        dyn.reset()
        for j in range(3):
            dyn.observe({"state": states[j]}, actions[j - 1] if j else None)
        errors[name] = float((dyn.response() - B).norm())
    assert errors["inferred"] < 0.5 * errors["fitted"], errors
    inferred.reset()
    for j in range(41):
        inferred.observe({"state": states[j]}, actions[j - 1] if j else None)
    found = inferred.response()
    prior = nominal_response(SIM, 1.0)
    assert found[dead, 3:].norm() < 0.2 * prior[dead, 3:].norm()
    live = [i for i in range(8) if i != dead]
    assert torch.allclose(found[live], B[live], atol=0.1 * float(prior[:8].abs().max()))


def test_a_flight_shows_the_network_what_training_showed_it(trained):
    """The inputs a flight's history gives the network are the ones the training cut before the
    same frame with the same history gives it (fuel at a whole percent, where both priors agree)."""
    model, config, _ = trained
    states, actions, _, _ = one_off_episode(np.random.default_rng(3))
    states[:, 15] = 0.5
    cuts = Cuts([(states, actions)], SIM, config)
    t, n = 30, 12
    inputs, _, _ = cuts.at(torch.tensor([t]), torch.tensor([n]))
    flight = InferredBodyDynamics(model, config, SIM, frames=n)
    for j in range(t - n, t + 1):
        flight.observe({"state": states[j]}, actions[j - 1] if j > t - n else None)
    with torch.no_grad():
        torch.testing.assert_close(flight.response(), model(*inputs)[0], rtol=1e-4, atol=1e-6)


def test_the_planner_flies_the_inferred_body_from_its_run_and_says_how_to_make_one(probed_run, trained, tmp_path):
    config = planner_config("cpu", body="inferred", horizon=10, samples=4)
    with pytest.raises(RunError, match="orbitmodel body"):
        build_pilot("planner", probed_run, config)
    with pytest.raises(RunError, match="RUN"):
        build_pilot("oracle-true", None, planner_config("cpu", obstacle_motion="true", body="inferred"))
    run = tmp_path / "run"
    shutil.copytree(probed_run, run)
    model, learned, card = trained
    save_inference(run, model, learned, card)
    pilot, _ = build_pilot("planner", run, config)
    assert isinstance(pilot.dynamics, FittedBodyLearnedDynamics)
    assert isinstance(pilot.dynamics.body, InferredBodyDynamics) and pilot.dynamics.body.frames == learned.frames
    assert recorded(config)["body"] == "inferred" and recorded(config)["fit_frames"] == 40
    assert "fit_ridge" not in recorded(config)  # the inference's own
    short, _ = build_pilot("planner", run, planner_config("cpu", body="inferred", fit_frames=2, horizon=10, samples=4))
    assert short.dynamics.body.frames == 2
    with pytest.raises(RunError, match="fit_frames=41"):
        build_pilot("planner", run, planner_config("cpu", body="inferred", fit_frames=41))
    published = {f.rel for f in run_files(run)}
    assert {"body/model.safetensors", "body/config.json"} <= published  # orbitmodel push takes the prior along
    again, same = load_inference(run)
    assert same == learned and all(
        torch.equal(a, b) for a, b in zip(again.state_dict().values(), model.state_dict().values())
    )


def test_orbitmodel_body_trains_into_the_run_and_keeps_what_is_there(
    probed_run, tiny_dataset_master, dynamic_master, tmp_path
):
    run = tmp_path / "run"
    shutil.copytree(probed_run, run)
    cli = CliRunner()
    static = cli.invoke(app, ["body", str(run), str(tiny_dataset_master), "--steps", "2"])
    assert static.exit_code == 2 and "static-tier dataset" in static.output and "--tier dynamic" in static.output
    assert "Traceback" not in static.output and not (run / "body").exists()
    args = ["body", str(run), str(dynamic_master), "--steps", "2"]
    bare = cli.invoke(app, args)  # the tiny run held no episodes out
    assert bare.exit_code == 2 and "no validation episodes" in bare.output and "Traceback" not in bare.output
    record = json.loads((run / "config.json").read_text())
    record["validation"]["episodes"] = [0]  # as a run trained with a validation fraction records them
    (run / "config.json").write_text(json.dumps(record))
    before = torch.get_num_threads()
    try:
        done = cli.invoke(app, [*args, "--threads", "1"])  # as the training commands take it, beside other work
        assert done.exit_code == 0, done.output
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
    assert (run / "body" / "model.safetensors").is_file() and "held-out prediction error" in done.output
    card = json.loads((run / "body" / "config.json").read_text())
    assert card["held_out_episodes"] == 1 and card["config"]["steps"] == 2
    assert card["training_episodes"] == len(flown_episodes(str(dynamic_master))) - 1
    again = cli.invoke(app, args)
    assert again.exit_code == 2 and "--overwrite" in again.output and "Traceback" not in again.output
