"""Closed loop: unseen seeds, a tiny episode end to end, the CLI's table, errors and Figure 6."""

from __future__ import annotations

import json

import pytest
import torch
from typer.testing import CliRunner

from orbitdata.seeding import episode_seed
from orbitmodel.cli.app import app
from orbitmodel.evaluate.closed_loop import (
    ClosedLoopRequest,
    check_unseen_seeds,
    closed_loop_report,
    dataset_seeds,
    fly_closed_loop,
    grid_seeds,
)
from orbitmodel.evaluate.figure6 import plot_figure6, read_report, success_table
from orbitmodel.plan.config import planner_config
from orbitmodel.plan.pilot import Variant

torch.set_num_threads(1)
runner = CliRunner()


@pytest.mark.parametrize("episodes", [3000, 8000])  # the 64 px dataset of this repo, and the README's
def test_grid_seeds_are_disjoint_from_the_datasets(episodes):
    grid = [s for *_, s in grid_seeds((1, 3, 5), (1.0, 2.0), 20, seed=0)]  # the default grid
    assert len(set(grid)) == len(grid) == 120
    assert not dataset_seeds(0, episodes) & set(grid)
    check_unseen_seeds(grid, 0, episodes)


def test_a_colliding_seed_is_refused():
    with pytest.raises(ValueError, match="another --seed"):
        check_unseen_seeds([episode_seed(0, 5)], root_seed=0, episodes=10)


def test_a_tiny_closed_loop_episode_runs_end_to_end(probed_run, tmp_path):
    req = ClosedLoopRequest(
        variant=Variant.PLANNER,
        run=probed_run,
        obstacles=(1,),
        speeds=(1.0,),
        episodes=1,
        settings=planner_config("paper", samples=8, horizon=5),
        max_steps=6,
        video_dir=tmp_path / "video",
        video_format=".gif",
    )
    result = fly_closed_loop(req)
    report = closed_loop_report(req, result)
    (cell,) = report["settings"]
    assert cell["episodes"] == 1 and sum(cell[o] for o in ("success", "collision", "timeout", "out_of_fuel")) == 1
    (episode,) = report["episodes"]
    assert episode["frames"] >= 2 and episode["replans"] == episode["frames"] - 1
    assert episode["nonfinite_actions"] == 0
    assert report["latency_ms"]["step"]["median"] > 0
    assert {"encode", "rollout", "probe", "cost", "depth-head"} <= set(report["time_share"])
    assert len(list((tmp_path / "video").glob("planner-obst1-v1-ep000-*.gif"))) == 1
    json.dumps(report)  # serialisable as it is


def test_the_planner_flies_through_orbitdatas_registry(probed_run):
    """`orbitdata fly --pilot planner --pilot-option run=RUN`: the entry point gives an
    orbitdata.fly.Pilot, and option strings become the planner's config."""
    import dataclasses

    from orbitdata.config import GenerationConfig
    from orbitdata.fly import Pilot, fly_grid, make_pilot

    base = GenerationConfig()
    sim = dataclasses.replace(base.sim, camera=dataclasses.replace(base.sim.camera, image_size=64), max_steps=4)
    config = dataclasses.replace(base, sim=sim)
    options = dict(run=str(probed_run), samples="8", horizon="5", memory_frames="3")
    pilot = make_pilot("planner", config, **options)
    assert isinstance(pilot, Pilot) and pilot.config.mppi.samples == 8 and pilot.config.memory_frames == 3
    (cell,) = fly_grid("planner", [1], [1.0], 1, config=config, **options)
    assert cell.episodes == 1 and cell.success + cell.collision + cell.timeout + cell.out_of_fuel == 1


def test_cli_prints_the_success_table_and_figure6_plots_it(probed_run, tmp_path):
    out = tmp_path / "planner.json"
    res = runner.invoke(
        app,
        [
            "eval",
            "closed-loop",
            str(probed_run),
            "--pilot",
            "oracle-true-dyn-depth",
            "--obstacles",
            "1",
            "--speeds",
            "1,2",
            "--episodes",
            "1",
            "--set",
            "samples=8",
            "--set",
            "horizon=5",
            "--max-steps",
            "4",
            "--set",
            "support=3",
            "--set",
            "margin_per_speed=0.15",
            "--set",
            "temperature=0.5",
            "--json",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "oracle-true-dyn-depth pilot, 1 episodes per setting, seed 0" in res.output and "success %" in res.output
    report = json.loads(out.read_text())
    assert report["preset"] == report["planner_preset"] == "cpu"  # the preset that suits a CPU, by default
    assert report["planner"]["support"] == 3 and report["planner"]["mppi"]["samples"] == 8
    assert report["planner"]["history"] == 2 and report["image_codec"] is False  # the rest is the cpu preset's
    assert report["planner"]["cost"]["margin_per_speed"] == 0.15 and report["planner"]["mppi"]["temperature"] == 0.5
    assert [(s["obstacles"], s["speed"]) for s in report["settings"]] == [(1, 1.0), (1, 2.0)]
    # Each episode was streamed as it landed; a grid stopped early is read back from that stream.
    streamed = read_report(tmp_path / "planner.episodes.jsonl")
    assert streamed["partial"] and streamed["pilot"] == "oracle-true-dyn-depth"
    assert [{k: s[k] for k in streamed["settings"][0]} for s in report["settings"]] == streamed["settings"]
    expert = {
        "pilot": "expert",
        "seed": 0,
        "settings": [
            {"obstacles": 1, "speed": v, "episodes": 1, "success": 1, "collision": 0, "timeout": 0, "out_of_fuel": 0}
            for v in (1.0, 2.0)
        ],
    }
    (tmp_path / "expert.json").write_text(json.dumps(expert))
    res = runner.invoke(
        app, ["eval", "figure6", str(tmp_path / "expert.json"), str(out), "--out", str(tmp_path / "fig6.png")]
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "fig6.png").stat().st_size > 1000
    settings, rates = success_table([expert, report])
    assert rates["expert"] == [1.0, 1.0, 1.0] and len(rates) == 2


def test_figure6_refuses_results_of_different_grids(tmp_path):
    a = {"pilot": "a", "seed": 0, "settings": [{"obstacles": 1, "speed": 1.0, "episodes": 2, "success": 1}]}
    b = {"pilot": "b", "seed": 0, "settings": [{"obstacles": 3, "speed": 1.0, "episodes": 2, "success": 1}]}
    with pytest.raises(ValueError, match="another grid"):
        plot_figure6([a, b], tmp_path / "f.png")


def one_line_error(res) -> str:
    assert res.exit_code == 2, res.output
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    return lines[0]


def test_bad_input_is_one_line_and_exit_2(tiny_run, tmp_path):
    base = ["eval", "closed-loop", "--episodes", "1", "--set", "samples=8", "--set", "horizon=5", "--max-steps", "3"]
    assert "no physics probe" in one_line_error(runner.invoke(app, base + [str(tiny_run)]))
    assert "give the run folder" in one_line_error(runner.invoke(app, base))
    assert "comma-separated" in one_line_error(
        runner.invoke(app, base + ["--pilot", "oracle-true", "--obstacles", ","])
    )
    assert "obstacle counts" in one_line_error(
        runner.invoke(app, base + ["--pilot", "oracle-true", "--obstacles", "-1"])
    )
    assert "'1,,3' must be a comma-separated list" in one_line_error(
        runner.invoke(app, base + ["--pilot", "oracle-true", "--obstacles", "1,,3"])
    )
    assert "obstacle counts must be 0 to 1000" in one_line_error(
        runner.invoke(app, base + ["--pilot", "oracle-true", "--obstacles", "99999999999999999999"])
    )
    toml = tmp_path / "camera.toml"
    toml.write_text("[sim.camera]\nimage_size = 128\n")
    assert "64 px" in one_line_error(
        runner.invoke(app, base + [str(tiny_run), "--pilot", "oracle-true-dyn-depth", "--config", str(toml)])
    )
    assert "not an orbitmodel run" in one_line_error(runner.invoke(app, base + [str(tmp_path)]))
    # a run's config.json given for the run: named as a file, with the folder to give instead
    line = one_line_error(runner.invoke(app, base + [str(tiny_run / "config.json")]))
    assert "is a file, not a run folder" in line and f"({tiny_run})" in line
    rigid = base + ["--pilot", "oracle-true"]
    assert "KEY=VALUE" in one_line_error(runner.invoke(app, rigid + ["--set", "urgency"]))
    assert "unknown planner option 'urgncy'" in one_line_error(runner.invoke(app, rigid + ["--set", "urgncy=1"]))
    assert "urgency='high': give a number" in one_line_error(runner.invoke(app, rigid + ["--set", "urgency=high"]))
    assert "true or false" in one_line_error(runner.invoke(app, rigid + ["--set", "image_codec=maybe"]))
    assert "samples=-5 must be >= 2" in one_line_error(runner.invoke(app, rigid + ["--set", "samples=-5"]))
    assert "presets are paper, cpu" in one_line_error(runner.invoke(app, rigid + ["--preset", "reference"]))
    # a table that could not be written at the end is refused before the first episode flies
    line = one_line_error(runner.invoke(app, rigid + ["--json", str(tmp_path)]))
    assert line.startswith(f"error: --json {tmp_path} is a folder") and not list(tmp_path.glob("*.episodes.jsonl"))


@pytest.mark.parametrize(
    "error, expected",
    [(ValueError("'x' must be finite\nsecond line"), "'x' must be finite"), (ZeroDivisionError(), "ZeroDivisionError")],
)
def test_a_flight_that_fails_midway_exits_1_and_keeps_what_landed(tmp_path, monkeypatch, error, expected):
    """A failure while the grid flies (a diverged rollout, say) is the flight's, not bad input:
    exit 1, one line naming how many episodes landed and the file that keeps them."""
    from orbitmodel.plan.pilot import OraclePilot

    resets, reset = [], OraclePilot.reset

    def second_fails(self, task, scenario=None):
        resets.append(task)
        if len(resets) == 2:
            raise error
        return reset(self, task, scenario)

    monkeypatch.setattr(OraclePilot, "reset", second_fails)
    out = tmp_path / "grid.json"
    args = ["eval", "closed-loop", "--pilot", "oracle-true", "--obstacles", "1", "--speeds", "1", "--episodes", "3"]
    res = runner.invoke(
        app, [*args, "--set", "samples=8", "--set", "horizon=5", "--max-steps", "3", "--json", str(out)]
    )
    kept = out.with_suffix(".episodes.jsonl")
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert errors == [f"error: the flight stopped after 1 episode: {expected}; those are in {kept}"]
    assert not out.exists() and len(kept.read_text().splitlines()) == 1


def test_a_video_path_that_is_a_file_is_refused_before_the_first_episode(tmp_path):
    (tmp_path / "ep0.gif").write_text("x")
    args = ["eval", "closed-loop", "--pilot", "oracle-true", "--obstacles", "1", "--speeds", "1", "--episodes", "1"]
    res = runner.invoke(app, [*args, "--max-steps", "3", "--video", str(tmp_path / "ep0.gif")])
    line = one_line_error(res)
    assert (
        res.exit_code == 2 and line == f"error: --video {tmp_path / 'ep0.gif'} is a file: give a folder for the videos"
    )
    assert "Episode" not in res.output and (tmp_path / "ep0.gif").read_text() == "x"


def test_grid_tables_that_are_not_grid_tables_are_one_line(tmp_path):
    """eval table, flips and figure6 name the file given and what to give instead."""
    (tmp_path / "other.json").write_text('{"a": 1}')
    (tmp_path / "broken.json").write_text("{")
    (tmp_path / "grid.json").write_text('{"pilot": "planner", "settings": []}')  # a table without its episodes
    for args, says in (
        (["table", str(tmp_path)], "is a folder"),
        (["table", str(tmp_path / "nope.json")], "does not exist"),
        (["table", str(tmp_path / "other.json")], "is not a grid result (it has no 'settings' key)"),
        (["table", str(tmp_path / "broken.json")], "is not JSON"),
        (["factors", str(tmp_path / "other.json")], "is not a grid result"),
        (["flips", str(tmp_path / "broken.json"), str(tmp_path / "other.json")], "is not JSON"),
        (["flips", str(tmp_path / "other.json"), str(tmp_path / "grid.json")], "is not a grid result"),
        (["flips", str(tmp_path / "grid.json"), str(tmp_path / "nope.json")], "does not exist"),
        (["flips", str(tmp_path / "grid.json"), str(tmp_path / "grid.json")], "holds no episodes"),
        (
            ["figure6", str(tmp_path / "other.json"), "--out", str(tmp_path / "f.txt")],
            "give a file matplotlib writes (",
        ),
    ):
        line = one_line_error(runner.invoke(app, ["eval", *args]))
        assert says in line and "give" in line, line
        assert line.count(str(tmp_path)) == 1, line  # the file named once


def test_an_output_that_could_not_be_written_is_refused_before_the_work(tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("x")
    for args, says in (
        (["figure6", str(taken), "--out", str(taken / "f.png")], f"--out {taken / 'f.png'}: {taken} is a file"),
        (["rollout", str(tmp_path), str(tmp_path), "--out", str(taken)], f"--out {taken} is a file: give a folder"),
        (["probe", str(tmp_path), str(tmp_path), "--out", str(taken / "t")], f"{taken} is a file, not a folder"),
    ):
        line = one_line_error(runner.invoke(app, ["eval", *args]))
        assert says in line, line
    assert taken.read_text() == "x"


def test_a_grid_flown_in_parts_merges_into_the_single_run_table(tmp_path):
    common = [
        "eval",
        "closed-loop",
        "--pilot",
        "oracle-true",
        "--obstacles",
        "1",
        "--episodes",
        "1",
        "--set",
        "samples=8",
        "--set",
        "horizon=5",
        "--max-steps",
        "4",
    ]
    for name, speeds in (("whole", "1,2"), ("v1", "1"), ("v2", "2")):
        res = runner.invoke(app, [*common, "--speeds", speeds, "--json", str(tmp_path / f"{name}.json")])
        assert res.exit_code == 0, res.output
    res = runner.invoke(
        app,
        [
            "eval",
            "merge",
            str(tmp_path / "v2.json"),
            str(tmp_path / "v1.json"),
            "--json",
            str(tmp_path / "merged.json"),
        ],
    )
    assert res.exit_code == 0, res.output
    whole, merged = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("whole", "merged"))
    assert merged["settings"] == whole["settings"]  # same seeds per setting: the same episodes
    same = lambda e: {k: e[k] for k in ("obstacles", "speed", "seed", "outcome", "frames", "fuel_used")}  # noqa: E731
    assert sorted(map(str, map(same, merged["episodes"]))) == sorted(map(str, map(same, whole["episodes"])))
    res = runner.invoke(
        app,
        [
            "eval",
            "merge",
            str(tmp_path / "v1.json"),
            str(tmp_path / "whole.json"),
            "--json",
            str(tmp_path / "bad.json"),
        ],
    )
    assert res.exit_code == 2 and "overlap" in res.output and "Traceback" not in res.output
    # a part flown on other kernels (ATEN_CPU_CAPABILITY=default) is another rounding: not one grid
    assert merged["cpu_capability"] == whole["cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    kernels = "DEFAULT" if merged["cpu_capability"] != "DEFAULT" else "AVX2"
    other = {**json.loads((tmp_path / "v1.json").read_text()), "cpu_capability": kernels}
    (tmp_path / "v1-default.json").write_text(json.dumps(other))
    res = runner.invoke(
        app,
        [
            "eval",
            "merge",
            str(tmp_path / "v2.json"),
            str(tmp_path / "v1-default.json"),
            "--json",
            str(tmp_path / "bad.json"),
        ],
    )
    assert res.exit_code == 2 and "cpu_capability" in res.output and "Traceback" not in res.output
    # a part flown with another flag is another grid: the refusal names the field and both values
    v1 = json.loads((tmp_path / "v1.json").read_text())
    samples = v1["planner"]["mppi"]["samples"]
    odd_parts = {
        "samples": (
            {**v1, "planner": {**v1["planner"], "mppi": {**v1["planner"]["mppi"], "samples": 16}}},
            f"planner.mppi.samples: {samples} -> 16",
        ),
        "max-steps": ({**v1, "max_steps": 40}, "max_steps: 4 -> 40"),
        "tier": ({**v1, "tier": "dynamic"}, "tier: None -> 'dynamic'"),
        "episodes": (
            {**v1, "settings": [{**s, "episodes": 2} for s in v1["settings"]]},
            "1 and 2 episodes per setting",
        ),
    }
    for name, (part, says) in odd_parts.items():
        (tmp_path / f"v1-{name}.json").write_text(json.dumps(part))
        res = runner.invoke(
            app,
            [
                "eval",
                "merge",
                str(tmp_path / "v2.json"),
                str(tmp_path / f"v1-{name}.json"),
                "--json",
                str(tmp_path / "bad.json"),
            ],
        )
        lines = res.output.strip().splitlines()
        assert res.exit_code == 2 and says in res.output and len(lines) == 1, (name, res.output)
    assert not (tmp_path / "bad.json").exists()


def test_a_merged_dynamic_grid_counts_every_parts_rejected_draws():
    from orbitmodel.evaluate.closed_loop import merge_reports

    def part(speed, rejected, kept):
        setting = {"obstacles": 3, "speed": speed, "episodes": 1, "success": 1}
        rejections = {"unsurvivable_draws": rejected, "debris": kept, "rate": rejected / (rejected + kept)}
        return {"pilot": "expert", "seed": 0, "tier": "dynamic", "rejections": rejections, "settings": [setting]}

    merged = merge_reports([part(1.0, 1, 3), part(3.0, 3, 3)])
    assert merged["rejections"] == {"unsurvivable_draws": 4, "debris": 6, "rate": 0.4}


def test_a_frame_step_run_trains_probes_and_flies(tiny_dataset_master, tmp_path, monkeypatch):
    """--frame-step 2: Stage I and the probe on steps of 2 frames, the planner imagining a 6-frame
    plan in 3 predictor calls; a horizon that is not a multiple of 2 is refused before flying."""
    from orbitmodel.config import get_preset
    from orbitmodel.probe.model import PhysicsProbe
    from orbitmodel.probe.train import ProbeRequest, train_probe
    from orbitmodel.runs import RunError
    from orbitmodel.train.stage1 import Stage1Request, train_world_model

    run = tmp_path / "skip2"
    preset = get_preset("tiny").with_model(frame_step=2).with_train(max_steps=2)
    train_world_model(Stage1Request(dataset=str(tiny_dataset_master), preset=preset, out=run, device="cpu"))
    train_probe(ProbeRequest(run=run, dataset=str(tiny_dataset_master), recipe=get_preset("tiny").probe, device="cpu"))
    assert PhysicsProbe.from_pretrained(run).config.dt == pytest.approx(0.08)  # two frames of 0.04 s
    # Table I per frame (the probe's states interpolated between steps), and the latent curves per step
    res = runner.invoke(
        app,
        [
            "eval",
            "probe",
            str(run),
            str(tiny_dataset_master),
            "--windows",
            "2",
            "--horizon",
            "4",
            "--horizon",
            "6",
            "--out",
            str(tmp_path / "eval"),
        ],
    )
    assert res.exit_code == 0, res.output
    table = json.loads((tmp_path / "eval" / "probe_table.json").read_text())
    assert table["frame_step"] == 2 and table["context"] == 7  # 4 latents: frames 0, 2, 4, 6
    assert len(table["table"]["probe"]["position"]["per_step"]) == 6
    note = (tmp_path / "eval" / "probe_table.md").read_text()  # no advice to train what is refused here
    assert "not trained for a frame-step run" in note and "--state-only` first" not in note
    odd = runner.invoke(app, ["eval", "probe", str(run), str(tiny_dataset_master), "--windows", "2", "--horizon", "5"])
    assert odd.exit_code == 2 and "multiples of 2" in odd.output
    res = runner.invoke(
        app,
        [
            "eval",
            "rollout",
            str(run),
            str(tiny_dataset_master),
            "--windows",
            "2",
            "--horizon",
            "3",
            "--out",
            str(tmp_path / "rollout"),
        ],
    )
    assert res.exit_code == 0, res.output
    curves = json.loads((tmp_path / "rollout" / "rollout.json").read_text())
    assert curves["frame_step"] == 2 and len(curves["nmse"]) == 3  # 3 steps of 2 frames
    req = ClosedLoopRequest(
        variant=Variant.PLANNER,
        run=run,
        obstacles=(1,),
        speeds=(1.0,),
        episodes=1,
        settings=planner_config("paper", samples=8, horizon=6),
        max_steps=6,
    )
    from orbitmodel.model.predictor import Predictor

    calls = []
    forward = Predictor.forward
    monkeypatch.setattr(Predictor, "forward", lambda self, *a, **k: calls.append(1) or forward(self, *a, **k))
    report = closed_loop_report(req, fly_closed_loop(req))
    (episode,) = report["episodes"]
    assert episode["replans"] == episode["frames"] - 1 and episode["nonfinite_actions"] == 0
    assert len(calls) == 3 * episode["replans"]  # each plan: 6 frames imagined in 3 predictor calls
    bad = ClosedLoopRequest(
        variant=Variant.PLANNER,
        run=run,
        obstacles=(1,),
        speeds=(1.0,),
        episodes=1,
        settings=planner_config("paper", samples=8, horizon=5),
        max_steps=6,
    )
    with pytest.raises(RunError, match="multiple of 2"):
        fly_closed_loop(bad)


def test_the_default_planner_preset_suits_the_machine(monkeypatch):
    """Without --preset a CPU flies the cpu preset (K 32) and a CUDA machine the paper's (K 256)."""
    from orbitmodel.evaluate.closed_loop import pilot_settings
    from orbitmodel.plan.config import default_planner_preset

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    settings, preset = pilot_settings(None)
    assert (preset, settings.mppi.samples, default_planner_preset()) == ("cpu", 32, "cpu")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    settings, preset = pilot_settings(None)
    assert (preset, settings.mppi.samples) == ("paper", 256)
    settings, preset = pilot_settings(None, samples="64")
    assert (preset, settings.mppi.samples) == ("paper", 64)
