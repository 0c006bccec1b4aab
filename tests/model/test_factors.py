"""``orbitmodel eval factors``: a grid's success by what its episodes were dealt, and how they flew."""

import json

import pytest
from typer.testing import CliRunner

from orbitmodel.cli.app import app
from orbitmodel.evaluate.factors import breakdown, factor_tables
from orbitmodel.evaluate.success import pool_seeds


def episode(k, outcome, fault="none", eclipse=False, frames=100, delta_v=10.0, clearance=0.5):
    return {
        "obstacles": 3,
        "speed": 1.0,
        "episode": k,
        "seed": 1000 + k,
        "outcome": outcome,
        "frames": frames,
        "min_clearance_m": clearance,
        "delta_v_mps": delta_v,
        "debris": 3,
        "debris_moving": 3,
        "fault": fault,
        "cw": k % 2 == 0,
        "eclipse": eclipse,
    }


def report(seed, episodes):
    counts = {o: sum(e["outcome"] == o for e in episodes) for o in ("success", "collision", "timeout", "tumbling")}
    setting = {"obstacles": 3, "speed": 1.0, "episodes": len(episodes), "out_of_fuel": 0, **counts}
    return {"pilot": "planner", "seed": seed, "settings": [setting], "episodes": episodes}


GRID = [
    episode(0, "success", frames=150, delta_v=12.0),
    episode(1, "success", frames=200, delta_v=20.0, eclipse=True),
    episode(2, "tumbling", fault="stuck", frames=60, clearance=0.2),
    episode(3, "success", fault="off", frames=250, delta_v=30.0),
    episode(4, "collision", fault="off", eclipse=True, frames=40, clearance=0.0),
]


def test_success_is_counted_within_each_factor_with_its_interval():
    b = breakdown(report(3, GRID))
    g = b["groups"]
    assert (g["no fault"]["success"], g["no fault"]["episodes"]) == (2, 2)
    assert (g["a fault"]["success"], g["a fault"]["episodes"]) == (1, 3)
    assert (g["off"]["success"], g["off"]["episodes"], g["stuck"]["episodes"], g["scaled"]["episodes"]) == (1, 2, 1, 0)
    assert (g["eclipse"]["success"], g["eclipse"]["episodes"], g["sunlit"]["episodes"]) == (1, 2, 3)
    assert g["debris still"]["episodes"] == 0 and g["debris moving"]["episodes"] == 5
    assert g["a fault"]["low"] == pytest.approx(0.0615, abs=1e-4)  # Wilson, 1 of 3
    f = b["flight"]
    assert (f["success"], f["collision"], f["tumbling"], f["timeout"]) == (3, 1, 1, 0)
    assert f["min_clearance_m_median"] == 0.5
    assert f["delta_v_mps_median_success"] == 20.0  # the successes' only: 12, 20, 30
    assert f["time_to_goal_s_median"] == pytest.approx(200 * 0.04)
    table = factor_tables([("planner", b)])
    assert "| planner | none flown | 60.0 % [23.1, 88.2] (3/5) | 100.0 % [34.2, 100.0] (2/2) |" in table
    assert "| planner | 5 | 3 | 1 | 0 | 1 | 0 | 0.50 | 20.0 | 8.0 |" in table


def test_a_static_grid_has_no_factors_and_a_pooled_grid_keeps_every_seeds_episodes():
    static = [{k: v for k, v in e.items() if k not in ("debris_moving", "fault", "cw", "eclipse")} for e in GRID]
    assert breakdown(report(0, static))["groups"] == {}
    pooled = pool_seeds([report(3, GRID[:3]), report(4, GRID[3:])])
    assert [e["seed"] for e in pooled["episodes"]] == [e["seed"] for e in GRID]
    assert breakdown(pooled)["groups"]["a fault"]["episodes"] == 3


def test_the_cli_prints_a_row_per_file_and_refuses_a_result_without_episodes(tmp_path):
    (tmp_path / "planner.json").write_text(json.dumps(report(3, GRID)))
    bare = report(3, GRID)
    del bare["episodes"]
    (tmp_path / "bare.json").write_text(json.dumps(bare))
    runner = CliRunner()
    out = tmp_path / "factors.json"
    res = runner.invoke(app, ["eval", "factors", str(tmp_path / "planner.json"), "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert "| planner | none flown |" in res.output
    assert json.loads(out.read_text())["planner"]["flight"]["success"] == 3
    res = runner.invoke(app, ["eval", "factors", str(tmp_path / "bare.json")])
    assert res.exit_code != 0 and "bare.json" in res.output and "holds no episodes" in res.output
    assert "Traceback" not in res.output


def test_files_of_one_name_keep_a_row_and_a_json_entry_each(tmp_path):
    """Two seeds' grids of one pilot share a file name; each keeps its own row and JSON entry."""
    for seed, episodes in ((3, GRID[:3]), (4, GRID[3:])):
        (tmp_path / f"seed{seed}").mkdir()
        (tmp_path / f"seed{seed}" / "planner.json").write_text(json.dumps(report(seed, episodes)))
    (tmp_path / "oracle.json").write_text(json.dumps(report(3, GRID)))
    out = tmp_path / "factors.json"
    files = [
        str(tmp_path / "seed3" / "planner.json"),
        str(tmp_path / "seed4" / "planner.json"),
        str(tmp_path / "oracle.json"),
    ]
    res = CliRunner().invoke(app, ["eval", "factors", *files, "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert "| seed3/planner | none flown |" in res.output and "| seed4/planner | none flown |" in res.output
    assert "| oracle | none flown |" in res.output
    written = json.loads(out.read_text())
    assert sorted(written) == ["oracle", "seed3/planner", "seed4/planner"]
    assert (written["seed3/planner"]["flight"]["episodes"], written["seed4/planner"]["flight"]["episodes"]) == (3, 2)
