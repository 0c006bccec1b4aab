"""The planner flown with Table I's probes (issue 37, deliverable 3): ``--set probe=NAME`` on a tiny
run stepping 2 frames whose probe is trained as the flown one (per frame, latents and thrusts).
The thrust-only planner never calls the predictor and plans the same whatever the imagined latents;
a planner reading a latent probe imagines what that probe predicts; a missing variant is one line;
lockstep and unbatched thrust-only flights agree."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from orbitdata.fly.pilot import Task
from orbitmodel.cli.app import app
from orbitmodel.data import group_actions
from orbitmodel.evaluate.closed_loop import ClosedLoop, ClosedLoopRequest
from orbitmodel.evaluate.success import pool_seeds
from orbitmodel.plan.config import planner_config
from orbitmodel.plan.factory import build_pilot
from orbitmodel.plan.pilot import Variant
from orbitmodel.probe import PhysicsProbe
from orbitmodel.runs import RunError

torch.set_num_threads(1)
runner = CliRunner()
STEP = 2  # frames per world-model step
CANDIDATE = "latent_probe-z-steps-noinc"  # a latent-only candidate: z_k alone, one state per latent
SMALL = dict(samples=8, horizon=6)


def invoke(*args):
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def run(tiny_dataset_master, tmp_path_factory):
    """The run with its flown probe, the thrust-only and paper probes and one latent-only candidate,
    chosen as the run's latent_probe (``RUN/latent_probe.json``, as ``eval probe --split val`` writes it)."""
    from orbitmodel.config import get_preset
    from orbitmodel.probe import table1
    from orbitmodel.probe.table1 import Rows
    from orbitmodel.train.stage1 import Stage1Request, train_world_model

    run, data = tmp_path_factory.mktemp("variants") / "wm", str(tiny_dataset_master)
    preset = get_preset("tiny").with_model(frame_step=STEP).with_train(max_steps=2)
    train_world_model(Stage1Request(dataset=data, device="cpu", out=run, preset=preset))
    invoke("probe", run, data, "--device", "cpu", "--per-frame", "--inputs", "latent+change+thrust")
    for variant in ("thrust_only", "paper_probe", CANDIDATE):
        invoke("probe", run, data, "--device", "cpu", "--variant", variant)
    from orbitmodel.model.world_model import WorldModel

    fp = WorldModel.from_pretrained(run).fingerprint
    chosen = PhysicsProbe.from_pretrained(run, variant=CANDIDATE)
    facts = dict(split="val", windows=1, seed=0, histories=[2], horizons=[2])
    table1.save_choice(
        run, {**facts, "latent_probe": {"chosen": CANDIDATE, "scores": {}}}, Rows({CANDIDATE: chosen}), fp
    )
    return run


def planner(run, probe: str = "", **changes):
    return build_pilot(Variant.PLANNER, run, planner_config("cpu", probe=probe, **{**SMALL, **changes}))[0]


def observation(rng: np.random.Generator, t: int) -> dict:
    """A 64 px frame and a state flying along +x (identity attitude, full tank)."""
    state = np.zeros(16, np.float32)
    state[0], state[3], state[6], state[9], state[15] = 0.04 * t, 1.0, 1.0, 1.0, 1.0
    return {"image": rng.integers(0, 255, (64, 64, 3), dtype=np.uint8), "state": state}


def fly(pilot, frames: int = 6) -> np.ndarray:
    """The pilot's thrusts on the same synthetic frames, every time."""
    pilot.reset(Task(goal=(10.0, 0.0, 0.0), goal_radius=0.5, initial_velocity=(1.0, 0.0, 0.0), seed=3))
    rng = np.random.default_rng(0)
    return np.stack([pilot.act(observation(rng, t)) for t in range(frames)])


def predictor_calls(pilot) -> list:
    calls = []
    pilot.dynamics.model.predictor.register_forward_hook(lambda *_: calls.append(1))
    return calls


def scramble_predictor(pilot) -> None:
    """Other imagined latents: the predictor's weights moved far from the trained ones."""
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in pilot.dynamics.model.predictor.parameters():
            p.add_(torch.randn(p.shape, generator=g))


def test_the_thrust_only_planner_never_calls_the_predictor_and_ignores_the_latents(run):
    flown, alone = planner(run), planner(run, "thrust_only")
    assert alone.dynamics.probe.config.inputs == "thrust" and not alone.dynamics.reads_latent
    flown_calls, alone_calls = predictor_calls(flown), predictor_calls(alone)
    flown_plan, alone_plan = fly(flown), fly(alone)
    assert len(flown_calls) > 0 and alone_calls == []  # the flown planner imagines; the thrust-only one does not
    assert "rollout" not in alone.timings.snapshot() and alone.timings.snapshot()["depth-head"] > 0
    scrambled = planner(run, "thrust_only")
    scramble_predictor(scrambled)
    assert np.array_equal(fly(scrambled), alone_plan)  # whatever the latents would be, the same plan
    moved = planner(run)
    scramble_predictor(moved)
    assert not np.array_equal(fly(moved), flown_plan)  # where the probe reads them, they move the plan


def imagined(pilot, frames: int = 3, K: int = 4):
    """The pilot's imagined states for K plans after ``frames`` observed frames, with what went in:
    the images, the states and the thrusts taken between frames, and the plans."""
    rng = np.random.default_rng(5)
    obs = [observation(rng, t) for t in range(frames)]
    taken = rng.uniform(0, 1, (frames - 1, 8)).astype(np.float32)
    pilot.dynamics.reset()
    for t, o in enumerate(obs):
        pilot.dynamics.observe(o, None if t == 0 else taken[t - 1])
    plans = torch.rand(K, SMALL["horizon"], 8, generator=torch.Generator().manual_seed(2))
    state0 = torch.as_tensor(obs[-1]["state"])
    return pilot.dynamics.rollout(state0, plans), obs, taken, plans


@pytest.mark.parametrize("probe", ["paper_probe", CANDIDATE, "latent_probe", "thrust_only"])
def test_a_planner_imagines_what_its_probe_variant_predicts(run, probe):
    """The states a planner imagines for a plan equal the variant's own predictions, computed here as
    ``eval probe`` computes a row: the run's world model encodes the frames and rolls the plan out
    from the last 2 latents (frames 0 and 2), the variant's probe reads them from the last state."""
    from orbitmodel.model.world_model import WorldModel

    states, obs, taken, plans = imagined(planner(run, probe))
    variant = CANDIDATE if probe == "latent_probe" else probe
    own = PhysicsProbe.from_pretrained(run, variant=variant)
    model = WorldModel.from_pretrained(run)
    K = len(plans)
    with torch.no_grad():
        images = torch.as_tensor(np.stack([obs[0]["image"], obs[2]["image"]])).permute(0, 3, 1, 2)[None]
        z = model.encode(images, torch.as_tensor(np.stack([obs[0]["state"], obs[2]["state"]]))[None])  # (1, 2, D)
        steps = group_actions(torch.cat([torch.as_tensor(taken)[None].expand(K, -1, -1), plans], 1), STEP)  # (K, 4, 16)
        future = steps[:, 1:]  # the plan's 3 steps of 2 frames
        z_future = model.rollout(z.expand(K, -1, -1), steps, 2)  # (K, 3, D)
        if probe == "thrust_only":  # reads no latent: any latents give its states
            z_future = torch.randn_like(z_future)
        state0 = torch.as_tensor(obs[2]["state"]).expand(K, -1)
        expected = own.per_frame(z_future, state0, z[:, -1].expand(K, -1), STEP, future)
    assert states.shape == expected.shape == (K, SMALL["horizon"], 16)
    assert torch.allclose(states, expected, atol=1e-5)
    others = {"paper_probe": CANDIDATE, CANDIDATE: "paper_probe", "latent_probe": "", "thrust_only": ""}
    assert not torch.allclose(states, imagined(planner(run, others[probe]))[0], atol=1e-3)  # the probe matters


def test_a_missing_variant_is_one_line_naming_its_folder_and_command(run, tmp_path):
    missing = "latent_probe-change-frames-inc"
    with pytest.raises(RunError) as err:
        planner(run, missing)
    message = str(err.value)
    assert "\n" not in message and str(run / f"probe-{missing}") in message
    assert f"`orbitmodel probe {run} DATASET --variant {missing}`" in message
    choice = run / "latent_probe.json"
    kept = choice.read_text()
    choice.unlink()
    try:
        with pytest.raises(RunError, match=f"choose it with `orbitmodel eval probe {run} DATASET --split val`"):
            planner(run, "latent_probe")
    finally:
        choice.write_text(kept)
    grid = ["--obstacles", "1", "--speeds", "1", "--episodes", "1", "--max-steps", "3", "--set", "samples=8"]
    for value, says in ((missing, f"--variant {missing}"), ("nope", "probe='nope'")):
        res = runner.invoke(app, ["eval", "closed-loop", str(run), "--preset", "cpu", *grid, "--set", f"probe={value}"])
        assert res.exit_code == 2 and says in res.output and res.output.count("\n") == 1, res.output
    with pytest.raises(ValueError, match="rigid-body model, which reads no probe"):
        build_pilot(Variant.ORACLE_TRUE, None, planner_config("cpu", probe="thrust_only"))


def request(run, batch: int, probe: str = "thrust_only") -> ClosedLoopRequest:
    return ClosedLoopRequest(
        run=run,
        settings=planner_config("cpu", probe=probe, **SMALL),
        preset="cpu",
        obstacles=(1,),
        speeds=(1.0, 2.0),
        episodes=1,
        seed=7,
        max_steps=20,
        batch=batch,
    )


def test_thrust_only_flights_in_lockstep_fly_the_unbatched_episodes_and_record_the_probe(run):
    one, two = ClosedLoop(request(run, 1)), ClosedLoop(request(run, 2))
    a, b = one.report(one.fly()), two.report(two.fly())
    assert [e["seed"] for e in b["episodes"]] == [e["seed"] for e in a["episodes"]] and len(a["episodes"]) == 2
    assert [e["outcome"] for e in b["episodes"]] == [e["outcome"] for e in a["episodes"]]
    assert [e["frames"] for e in b["episodes"]] == [e["frames"] for e in a["episodes"]]
    assert [e["min_clearance_m"] for e in b["episodes"]] == [e["min_clearance_m"] for e in a["episodes"]]
    assert a["planner"]["probe"] == "thrust_only" and "rollout" not in a["time_share"]
    flown = ClosedLoop(request(run, 1, probe=""))
    default = flown.report(flown.fly())
    assert "probe" not in default["planner"]  # the run's own probe records the same settings as ever
    with pytest.raises(ValueError, match="seed 7 was flown with probe thrust_only, seed 8 with the run's own"):
        pool_seeds([{**default, "seed": 8}, a])  # the planner reading another probe is another way of flying


def test_the_probe_setting_travels_through_the_cli_and_orbitdatas_registry(run, tmp_path):
    import dataclasses

    from orbitdata.config import GenerationConfig
    from orbitdata.fly import make_pilot

    out = tmp_path / "thrust-only.json"
    grid = ["--obstacles", "1", "--speeds", "1", "--episodes", "1", "--max-steps", "3"]
    small = ["--set", "samples=8", "--set", "horizon=6", "--set", "probe=thrust_only"]
    invoke("eval", "closed-loop", run, "--pilot", "planner", "--preset", "cpu", *grid, *small, "--json", out)
    assert json.loads(out.read_text())["planner"]["probe"] == "thrust_only"
    base = GenerationConfig()
    sim = dataclasses.replace(base.sim, camera=dataclasses.replace(base.sim.camera, image_size=64))
    options = dict(run=str(run), preset="cpu", samples="8", horizon="6", probe="paper_probe")
    pilot = make_pilot("planner", dataclasses.replace(base, sim=sim), **options)
    assert pilot.config.probe == "paper_probe" and pilot.dynamics.probe.config.inputs == "latent"


def test_the_imagined_depth_planner_flies_through_the_cli_with_a_probe_that_reads_latents_only(
    run, tiny_dataset_master, tmp_path
):
    from orbitmodel.plan.depth_recipe import ImaginedDepthConfig
    from orbitmodel.plan.imagined import ImaginedField
    from orbitmodel.plan.imagined_fit import fit_imagined_depth

    small = ImaginedDepthConfig(windows=4, test_windows=2, horizon=6, hidden=16, epochs=1, batch_size=4)
    fit_imagined_depth(run, str(tiny_dataset_master), small, overwrite=True)
    out = tmp_path / "imagined.json"
    grid = ["--obstacles", "1", "--speeds", "1", "--episodes", "1", "--max-steps", "3"]
    moves = ["--set", "samples=8", "--set", "horizon=6", "--set", "obstacle_motion=imagined"]
    invoke("eval", "closed-loop", run, "--pilot", "planner", "--preset", "cpu", *grid, *moves, "--json", out)
    report = json.loads(out.read_text())
    assert report["planner"]["obstacle_motion"] == "imagined" and "imagined-depth" in report["time_share"]
    pilot, _ = build_pilot(Variant.PLANNER, run, planner_config("cpu", obstacle_motion="imagined", **SMALL))
    pilot.reset(Task((5.0, 0, 0), 0.5, (0.0, 0, 0), 0))
    rng = np.random.default_rng(0)
    obs = {
        "image": rng.integers(0, 255, (64, 64, 3), dtype=np.uint8),
        "state": np.r_[np.zeros(6), 1, 0, 0, 1, 0, 0, np.zeros(3), 1],
    }
    pilot.act(obs)
    states = torch.zeros(8, 6, 16)
    assert isinstance(pilot.round_field(None, states), ImaginedField)  # 3 steps of 2 frames, one map each
    with pytest.raises(ValueError, match="imagines no latents"):
        build_pilot(
            Variant.PLANNER, run, planner_config("cpu", obstacle_motion="imagined", probe="thrust_only", **SMALL)
        )
