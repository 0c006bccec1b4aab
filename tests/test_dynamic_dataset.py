"""A dataset of the dynamic tier: its columns hold the episode's record, every reader reads them,
the bytes do not depend on the workers or on re-sharding, and no learned pilot's loader sees a
privileged column. (The kill -9 and resume test of both tiers is in tests/write/test_generate.py.)"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from tiny import dynamic_config
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitdata.cli.app import app
from orbitdata.load.episodes import dynamics_record, load_episode, read_episodes
from orbitdata.scenario.dynamics import Dynamics
from orbitdata.scenario.sampler import sample_scenario
from orbitdata.viz import overview_figure
from orbitdata.write.finalize import finalize
from orbitdata.write.generate import generate

runner = CliRunner()


def tree_digest(root: Path) -> dict:
    import hashlib

    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _float32(value):
    """A record's numbers as the float32 columns store them (nested dicts and lists alike)."""
    if isinstance(value, dict):
        return {k: _float32(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_float32(v) for v in value]
    if isinstance(value, float):
        return float(np.float32(value))
    return value


def test_the_tables_are_the_static_columns_then_the_tiers(dynamic_master):
    steps = pq.read_schema(dynamic_master / "data" / "train-00000-of-00001.parquet")
    episodes = pq.read_schema(dynamic_master / "episodes" / "train-00000-of-00001.parquet")
    static_steps = [f.name for f in S.step_fields()]
    static_episodes = [f.name for f in S.episode_fields()]
    assert steps.names == static_steps + [S.OBSTACLE_POSES]
    assert episodes.names == static_episodes + list(S.DYNAMICS_COLUMNS.values())
    # The static tier's schemas are today's, untouched.
    assert S.step_schema("static").equals(S.STEP_SCHEMA) and S.episode_schema("static").equals(S.EPISODE_SCHEMA)
    info = json.loads((dynamic_master / S.INFO_PATH).read_text())
    assert info["config"]["scenario"]["tier"] == "dynamic"
    assert info["features"][S.OBSTACLE_POSES]["privileged"] is True
    # Its counts name the tier's outcomes; a static dataset's keep the static ones.
    assert set(info["counts"]["splits"]["train"]["outcomes"]) == set(S.outcomes("dynamic")) != set(S.OUTCOMES)
    # The schema names the tiers below the scenario package: the names agree.
    from orbitdata.scenario.config import DYNAMIC, STATIC

    assert (S.STATIC_TIER, S.DYNAMIC_TIER) == (STATIC, DYNAMIC)


def test_the_columns_are_the_scenarios_record(dynamic_master):
    """Each episode row carries its scenario's Dynamics and every frame its obstacles' poses,
    as a fresh draw of the same seed has them."""
    config = dynamic_config()
    episodes = read_episodes(dynamic_master).to_pylist()
    assert len(episodes) == 6
    for row in episodes:
        scenario = sample_scenario(row[S.SEED], config.scenario)
        record = dynamics_record(row)
        assert record == _float32(dataclasses.asdict(scenario.dynamics)), row[S.EPISODE_INDEX]
        episode = load_episode(dynamic_master, row[S.EPISODE_INDEX])
        assert isinstance(episode.scenario.dynamics, Dynamics)
        assert episode.scenario.dynamics.fault.kind == scenario.dynamics.fault.kind
        poses = episode.obstacle_poses  # (L, N, 7)
        assert poses.shape == (row[S.LENGTH], row[S.N_OBSTACLES], 7)
        expected = scenario.obstacle_poses(np.arange(row[S.LENGTH]) * S.DT)
        centres_moved = np.linalg.norm(expected[-1, :, :3] - expected[0, :, :3], axis=1)
        assert (centres_moved > 0).all()  # the debris moves, so a frame mix-up would show
        np.testing.assert_allclose(poses[..., :3], expected[..., :3], atol=1e-5)
        # A quaternion and its negative are the same attitude.
        dots = np.abs(np.sum(poses[..., 3:] * expected[..., 3:], axis=-1))
        np.testing.assert_allclose(dots, 1.0, atol=1e-5)


def test_datasets_pyarrow_polars_and_duckdb_read_the_new_columns(dynamic_master):
    import duckdb
    import polars as pl
    from datasets import load_dataset

    path = dynamic_master / "data" / "train-00000-of-00001.parquet"
    arrow = pq.read_table(path)
    poses = arrow.column(S.OBSTACLE_POSES).to_pylist()
    assert pl.read_parquet(path)[S.OBSTACLE_POSES].to_list() == poses
    rows = duckdb.sql(f'select "{S.OBSTACLE_POSES}" from \'{path}\' order by "{S.EPISODE_INDEX}", frame_index')
    assert [list(map(list, r[0])) for r in rows.fetchall()] == poses
    steps = load_dataset(str(dynamic_master), split="train")
    assert steps[S.OBSTACLE_POSES] == poses
    assert steps[0][S.IMAGE].size == (32, 32)

    episodes = load_dataset(str(dynamic_master), "episodes", split="train")
    path = dynamic_master / "episodes" / "train-00000-of-00001.parquet"
    table = pq.read_table(path)
    for name in S.DYNAMICS_COLUMNS.values():
        assert episodes[name] == table.column(name).to_pylist(), name
        assert pl.read_parquet(path)[name].to_list() == table.column(name).to_pylist(), name
    faults = duckdb.sql(f"select fault.kind from '{dynamic_master}/episodes/*.parquet'").fetchall()
    assert sorted(f[0] for f in faults) == sorted(r[S.FAULT]["kind"] for r in read_episodes(dynamic_master).to_pylist())


def test_workers_one_and_two_give_identical_bytes(dynamic_master, tmp_path):
    out = tmp_path / "two" / "orbit"
    generate(out, dynamic_config(), workers=2, figure=overview_figure)
    assert tree_digest(out) == tree_digest(dynamic_master)


def test_reshard_round_trip_reproduces_the_bytes(dynamic_master, tmp_path):
    import shutil

    copy = tmp_path / "orbit"
    shutil.copytree(dynamic_master, copy)
    finalize(copy, max_shard_bytes=20_000, figure=overview_figure)
    assert len(list(copy.glob("data/train-*.parquet"))) > 1
    assert read_episodes(copy).to_pylist() != read_episodes(dynamic_master).to_pylist()  # other shards
    finalize(copy, max_shard_bytes=500_000_000, figure=overview_figure)
    assert tree_digest(copy) == tree_digest(dynamic_master)


def test_the_card_lists_the_tiers_columns_and_its_rejections(dynamic_master):
    card = (dynamic_master / S.CARD_PATH).read_text()
    assert f"| `{S.OBSTACLE_POSES}` |" in card and f"| `{S.FAULT}` |" in card
    rejected = sum(r[S.UNSURVIVABLE_DRAWS] for r in read_episodes(dynamic_master).to_pylist())
    kept = sum(r[S.N_OBSTACLES] for r in read_episodes(dynamic_master).to_pylist())
    assert f"{rejected} debris draws were rejected as unsurvivable against {kept} kept" in card
    header = card.split("---")[1]
    assert S.OBSTACLE_POSES in header  # the Hub's feature list
    outcomes = " | ".join(o.replace("_", " ") for o in S.outcomes("dynamic"))
    assert f"| split | episodes | frames | {outcomes} |" in card


# ---- privileged columns never reach a learned pilot ------------------------------------------
def test_default_windows_hold_no_privileged_column(dynamic_master):
    from orbitdata.load import load_windows

    for streaming in (False, True):
        windows = load_windows(dynamic_master, split="train", context=2, horizon=2, streaming=streaming)
        item = next(iter(windows)) if streaming else windows[0]
        assert S.STATE in item and S.IMAGE in item
        assert not [k for k in item if S.is_privileged(k)], sorted(item)
    with pytest.raises(ValueError, match="privileged"):
        load_windows(dynamic_master, split="train", context=2, horizon=2, columns=[S.OBSTACLE_POSES])[0]


def test_orbitmodel_reads_no_privileged_column(dynamic_master):
    """Every training path of orbitmodel names its columns, none privileged, and a model's windows
    of a dynamic dataset hold none."""
    import orbitmodel
    from orbitmodel.baselines.diffusion import expert_floor
    from orbitmodel.baselines.diffusion import train as diffusion_train
    from orbitmodel.data import load_model_windows
    from orbitmodel.evaluate import rollout
    from orbitmodel.plan import imagined_fit
    from orbitmodel.probe import train as probe_train
    from orbitmodel.train import stage1

    named = [
        *stage1.COLUMNS,
        *rollout.COLUMNS,
        *diffusion_train.COLUMNS,
        *expert_floor.COLUMNS,
        *imagined_fit.COLUMNS,
        *(c for cols in probe_train.COLUMNS.values() for c in cols),
    ]
    assert named and not [c for c in named if S.is_privileged(c)]
    root = Path(orbitmodel.__file__).parent
    mentions = [
        str(p.relative_to(root))
        for p in root.rglob("*.py")
        if re.search(r"OBSTACLE_POSES|privileged\.|DEBRIS_MOTION|S\.FAULT\b|S\.BODY\b", p.read_text())
    ]
    assert not mentions, f"orbitmodel reads privileged columns in {mentions}"
    windows = load_model_windows(dynamic_master, 2, split="train", context=2, horizon=1, columns=list(stage1.COLUMNS))
    assert not [k for k in windows[0] if S.is_privileged(k)]


# ---- the CLI -----------------------------------------------------------------------------------
def test_a_config_of_another_tier_than_the_flag_is_a_usage_error(tmp_path):
    toml = tmp_path / "static.toml"
    toml.write_text('[scenario]\ntier = "static"\n')
    for command in (["generate", str(tmp_path / "out")], ["fly"]):
        res = runner.invoke(app, [*command, "--tier", "dynamic", "--config", str(toml)])
        assert res.exit_code == 2, res.output
        line = res.output.strip()
        assert "\n" not in line and "--tier dynamic" in line and "'static'" in line, line
    # A file that names no tier takes the flag's, under its own settings.
    toml.write_text("[scenario]\nn_obstacles = [2, 3]\n")
    from orbitdata.cli.generate import Tier, load_config

    cfg = load_config(toml, Tier.dynamic)
    assert cfg.tier == "dynamic" and cfg.scenario.n_obstacles == (2, 3) and cfg.scenario.speed == (0.5, 3.0)


def test_fly_records_the_tier_and_its_rejections(tmp_path):
    out = tmp_path / "dynamic.json"
    args = ["fly", "--pilot", "expert", "--obstacles", "3", "--speeds", "3", "--episodes", "2", "--json", str(out)]
    res = runner.invoke(app, [*args, "--tier", "dynamic"])
    assert res.exit_code == 0, res.output
    report = json.loads(out.read_text())
    assert report["tier"] == "dynamic"
    rejections = report["rejections"]
    # Each episode's world drawn again from its recorded seed: the report counts its pieces and
    # the draws rejected on the way to them, and their rate.
    from orbitdata.config import GenerationConfig
    from orbitdata.scenario.sampler import sample_scenario

    scenario = GenerationConfig.for_tier("dynamic").scenario
    worlds = [sample_scenario(e["seed"], scenario, 3, 3.0) for e in report["episodes"]]
    rejected = sum(w.dynamics.unsurvivable_draws for w in worlds)
    assert rejections["debris"] == sum(len(w.obstacles) for w in worlds) == 2 * 3
    assert rejections["unsurvivable_draws"] == rejected
    assert rejections["rate"] == pytest.approx(rejected / (rejected + 6))
    successes = report["settings"][0]["success"]
    assert f"pooled: {successes}/2 success" in res.output
    # The static tier's JSON has no tier and no rejections.
    res = runner.invoke(app, [*args[:2], "risky", *args[3:]])
    assert res.exit_code == 0, res.output
    static = json.loads(out.read_text())
    assert "tier" not in static and "rejections" not in static
    assert re.search(r"pooled: \d/2 success", res.output)


def test_resuming_a_dynamic_dataset_without_its_tier_names_the_tier_not_overwrite(dynamic_master):
    result = CliRunner().invoke(app, ["generate", str(dynamic_master), "--episodes", "6"])
    assert result.exit_code == 2
    line = result.output.strip().splitlines()[-1]
    assert "holds a dynamic-tier dataset; pass --tier dynamic to resume it" in line
    assert "--overwrite" not in line
