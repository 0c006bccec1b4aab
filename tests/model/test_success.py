"""Success rates come with their 95 % Wilson interval and episode count (``orbitmodel eval table``)."""

import json

import pytest
from typer.testing import CliRunner

from orbitmodel.cli.app import app
from orbitmodel.evaluate.success import failures_text, markdown_table, rate_text, wilson


def test_wilson_matches_the_textbook_values():
    low, high = wilson(117, 120)  # 97.5 %
    assert (round(100 * low, 1), round(100 * high, 1)) == (92.9, 99.1)
    low, high = wilson(0, 20)
    assert low == 0.0 and high == pytest.approx(0.1611, abs=1e-4)  # never a zero-width interval at 0 %
    low, high = wilson(20, 20)
    assert high == 1.0 and low == pytest.approx(0.8389, abs=1e-4)
    assert rate_text(110, 120) == "91.7 % [85.3, 95.4] (110/120)"
    for bad in ((1, 0), (-1, 5), (6, 5)):
        with pytest.raises(ValueError):
            wilson(*bad)


def grid(pilot, successes, collisions=0, timeouts=0):
    return {
        "pilot": pilot,
        "seed": 0,
        "settings": [
            {"obstacles": n, "speed": v, "episodes": 20, "success": k, "collision": c, "timeout": t, "out_of_fuel": 0}
            for (n, v), k, c, t in zip([(1, 1.0), (5, 2.0)], successes, collisions or [0, 0], timeouts or [0, 0])
        ],
    }


def test_the_table_gives_counts_the_interval_and_the_failures(tmp_path):
    planner = grid("planner", [19, 18], collisions=[1, 1], timeouts=[0, 1])
    table = markdown_table([grid("expert", [20, 20]), planner])
    assert "| planner | 19/20 | 18/20 | 92.5 % [80.1, 97.4] (37/40) | 2 collisions, 1 timeout |" in table
    assert failures_text(grid("expert", [20, 20])) == "none"
    assert "95 [76, 99]" in markdown_table([planner], per_setting_ci=True)
    with pytest.raises(ValueError, match="another grid"):
        markdown_table([planner, {**planner, "settings": planner["settings"][:1]}])
    for name, report in (("expert", grid("expert", [20, 20])), ("planner", planner)):
        (tmp_path / f"{name}.json").write_text(json.dumps(report))
    res = CliRunner().invoke(app, ["eval", "table", str(tmp_path / "expert.json"), str(tmp_path / "planner.json")])
    assert res.exit_code == 0, res.output
    assert "(40/40)" in res.output and f"[planner.json]({tmp_path / 'planner.json'})" in res.output


def test_flips_count_the_episodes_whose_outcome_changed(tmp_path):
    from orbitmodel.evaluate.success import outcome_flips

    def report(outcomes, clearances=(0.5, 0.5, 0.0, 0.3), frames=(100, 90, 40, 300)):
        return {
            "episodes": [
                {
                    "obstacles": 1,
                    "speed": 1.0,
                    "episode": k,
                    "seed": 100 + k,
                    "outcome": o,
                    "min_clearance_m": c,
                    "frames": n,
                }
                for k, (o, c, n) in enumerate(zip(outcomes, clearances, frames))
            ]
        }

    a = report(["success", "success", "collision", "timeout"])
    b = report(["success", "collision", "collision", "success"], (0.5, 0.0, 0.0, 0.7), (100, 60, 40, 200))
    result = outcome_flips(a, b)
    assert (result["episodes"], result["flips"], result["successes"]) == (4, 2, [2, 2])
    # how far the flights moved: 2 flown identically; closest approach changes 0, 0.5, 0, 0.4 m; frames 0, 30, 0, 100
    assert result["identical"] == 2
    assert result["clearance_change_m"] == pytest.approx({"median": 0.2, "max": 0.5})
    assert result["frames_change"] == {"median": 15.0, "max": 100}
    assert "identical" not in outcome_flips(
        report(["success"] * 4), {"episodes": [{k: v for k, v in e.items() if k != "frames"} for e in a["episodes"]]}
    )  # not recorded: not reported
    assert [(f["episode"], f["first"], f["second"]) for f in result["flipped"]] == [
        (1, "success", "collision"),
        (3, "timeout", "success"),
    ]
    with pytest.raises(ValueError, match="share no episode seed"):
        outcome_flips(a, {"episodes": [{**e, "seed": e["seed"] + 50} for e in a["episodes"]]})
    table = {"pilot": "planner", "seed": 0, "settings": [{"obstacles": 1, "speed": 1.0, "episodes": 4, "success": 2}]}
    (tmp_path / "a.json").write_text(json.dumps({**table, **a}))
    (tmp_path / "b.json").write_text(json.dumps({**table, **b}))
    flights = [str(tmp_path / "a.json"), str(tmp_path / "b.json")]
    res = CliRunner().invoke(app, ["eval", "flips", *flights, "--json", str(tmp_path / "flips.json")])
    assert res.exit_code == 0 and "2 of 4 episodes flip" in res.output and "success -> collision" in res.output
    assert "2 of 4 flown identically" in res.output
    written = json.loads((tmp_path / "flips.json").read_text())
    assert written["flights"] == flights and written["flips"] == 2  # it names the two flights it compares
    assert "only_first" not in written and "only_second" not in written  # the same episodes: nothing left out
    # a flight with an episode the other did not fly: the shared ones are compared, the others counted
    (tmp_path / "c.json").write_text(json.dumps({**table, "episodes": a["episodes"][:3]}))
    res = CliRunner().invoke(app, ["eval", "flips", str(tmp_path / "c.json"), flights[1]])
    assert res.exit_code == 0 and "1 of 3 episodes flip" in res.output
    assert f"compared the 3 episodes both flew: 0 more in {tmp_path / 'c.json'}, 1 more in {flights[1]}" in res.output


def test_pooling_seeds_sums_the_settings_and_names_the_worst(tmp_path):
    from orbitmodel.evaluate.success import pool_seeds, report_totals

    seeds = [
        {**grid("planner", k, collisions=[20 - k[0], 20 - k[1]]), "seed": s}
        for s, k in ((3, [20, 19]), (4, [17, 20]), (5, [20, 20]))
    ]
    pooled = pool_seeds(seeds)
    assert report_totals(pooled) == (116, 120) and pooled["seeds"] == [3, 4, 5]
    assert [s["collision"] for s in pooled["settings"]] == [3, 1]
    assert pooled["worst_setting"] == {
        "seed": 4,
        "obstacles": 1,
        "speed": 1.0,
        "rate": 0.85,
        "success": 17,
        "episodes": 20,
    }
    row = markdown_table([pooled]).splitlines()[2]  # a pooled table is a grid result like any other, plus its worst
    assert (
        row
        == "| planner | 57/60 | 59/60 | 96.7 % [91.7, 98.7] (116/120) | 4 collisions | 17/20 (seed 4, 1 obst. 1 m/s) |"
    )
    for bad, match in (
        ([seeds[0], seeds[0]], "repeat"),
        ([seeds[0], {**seeds[1], "pilot": "expert"}], "pilots differ"),
        ([seeds[0], {**seeds[1], "settings": seeds[1]["settings"][:1]}], "another grid"),
        ([seeds[0], {**seeds[1], "seed": None}], "root seed"),
        (
            [
                {**seeds[0], "pilot_settings": {"timestep_spacing": "leading"}},
                {**seeds[1], "pilot_settings": {"timestep_spacing": "trailing"}},
            ],
            "one way of flying",
        ),
        ([seeds[0], {**seeds[1], "image_codec": True}], "image_codec"),
        ([{**seeds[0], "preset": "cpu"}, {**seeds[1], "preset": "reference"}], "preset"),
        ([{**seeds[0], "run": "runs/a"}, {**seeds[1], "run": "runs/b"}], "run"),
        ([{**seeds[0], "max_steps": 300}, {**seeds[1], "max_steps": 30}], "max_steps"),
        (
            [{**seeds[0], "planner": {"samples": 32}}, {**seeds[1], "planner": {"samples": 8}}],
            "the planner's samples 8, seed 3 with 32",
        ),
    ):
        with pytest.raises(ValueError, match=match):
            pool_seeds(bad)
    newer = {
        **seeds[1],
        "planner": {"samples": 32, "added_later": 1},
    }  # a setting one version records and not the other
    assert pool_seeds([{**seeds[0], "planner": {"samples": 32}}, newer])["seeds"] == [3, 4]
    flown = [{**s, "preset": "cpu", "pilot_settings": {"draws": 1}, "image_codec": True} for s in seeds]
    assert {k: pool_seeds(flown)[k] for k in ("preset", "pilot_settings", "image_codec")} == {
        "preset": "cpu",
        "pilot_settings": {"draws": 1},
        "image_codec": True,
    }  # how the seeds flew, carried along
    for s in seeds:
        (tmp_path / f"seed{s['seed']}.json").write_text(json.dumps(s))
    res = CliRunner().invoke(
        app,
        ["eval", "pool", *(str(tmp_path / f"seed{k}.json") for k in (3, 4, 5)), "--json", str(tmp_path / "test.json")],
    )
    assert res.exit_code == 0, res.output
    assert "96.7 % [91.7, 98.7] (116/120)" in res.output and "seed 4, 1 obstacles at 1 m/s, 17/20" in res.output
    assert json.loads((tmp_path / "test.json").read_text())["seeds"] == [3, 4, 5]


def test_a_dynamic_grids_tumbling_is_a_failure_and_a_static_grids_keys_stay(tmp_path):
    from orbitmodel.evaluate.figure6 import report_from_episodes
    from orbitmodel.evaluate.success import pool_seeds

    static = [{**grid("risky", [18, 20], collisions=[2, 0]), "seed": s} for s in (0, 1)]
    assert set(pool_seeds(static)["settings"][0]) == set(static[0]["settings"][0])  # no tumbling key added
    dynamic = [
        {**r, "settings": [{**x, "tumbling": 1, "success": x["success"] - 1} for x in r["settings"]]} for r in static
    ]
    assert failures_text(dynamic[0]) == "2 collisions, 2 tumbling"
    assert [s["tumbling"] for s in pool_seeds(dynamic)["settings"]] == [2, 2]
    stream = tmp_path / "grid.episodes.jsonl"
    stream.write_text(
        "".join(json.dumps({"obstacles": 3, "speed": 1.0, "outcome": o}) + "\n" for o in ("success", "tumbling"))
    )
    cell = report_from_episodes(stream)["settings"][0]
    assert (cell["episodes"], cell["success"], cell["tumbling"]) == (2, 1, 1)


def test_a_planner_setting_left_at_its_default_pools_with_one_not_recorded():
    """Result files record the planner's fit knobs only when a body is fitted (``plan.config.recorded``);
    pooling reads a missing knob as its default, so the defaults it assumes must be PlannerConfig's."""
    from orbitmodel.evaluate.success import PLANNER_WAYS, pool_seeds
    from orbitmodel.plan.config import PlannerConfig, recorded

    default = PlannerConfig()
    for key in ("obstacle_motion", "body", "fit_frames", "fit_ridge", "fit_steps"):
        assert PLANNER_WAYS[key] == getattr(default, key), key
    seeds = [{**grid("planner", [20, 19]), "seed": s} for s in (3, 4)]
    plain = {**seeds[0], "planner": recorded(default)}
    explicit = {**seeds[1], "planner": {**recorded(default), "body": "true", "fit_frames": 40, "fit_steps": 1}}
    assert pool_seeds([plain, explicit])["seeds"] == [3, 4]
    other = {**seeds[1], "planner": {**recorded(default), "body": "true", "fit_steps": 2}}
    with pytest.raises(ValueError, match="fit_steps"):
        pool_seeds([plain, other])
