"""Episode filters through the episodes table: by value, by predicate, by index; empty or bad filters raise."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)
import pyarrow.parquet as pq
import pytest

from orbitdata import schema as S
from orbitdata.load import load_windows
from orbitdata.load.select import select_episodes


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("hf-cache"))


@pytest.fixture(scope="module")
def episodes(tiny_dataset_master):
    """The train episodes table, read straight from Parquet."""
    return pq.read_table(next((tiny_dataset_master / S.EPISODES_DIR).glob("train-*.parquet")))


def rows(table) -> list[dict]:
    return table.select([S.EPISODE_INDEX, S.LEVEL, S.OUTCOME, S.LENGTH]).to_pylist()


def test_filter_by_level_and_outcome_keeps_only_those_episodes(tiny_dataset_master, cache, episodes):
    level = rows(episodes)[0][S.LEVEL]
    outcome = rows(episodes)[0][S.OUTCOME]
    want = sorted(r[S.EPISODE_INDEX] for r in rows(episodes) if r[S.LEVEL] == level and r[S.OUTCOME] == outcome)
    ds = load_windows(
        tiny_dataset_master,
        context=2,
        horizon=2,
        episodes={S.LEVEL: [level], S.OUTCOME: outcome},
        columns=[S.ACTION],
        cache_dir=cache,
    )
    assert ds.episodes.tolist() == want
    assert set(np.unique(ds.index.episode).tolist()) == set(want)
    for i in (0, len(ds) - 1):
        assert int(ds[i][S.EPISODE_INDEX][0]) in want


def test_callable_filter_gives_collision_free_windows(tiny_dataset_master, cache, episodes):
    ds = load_windows(
        tiny_dataset_master,
        context=2,
        horizon=2,
        columns=[S.COLLISION],
        cache_dir=cache,
        episodes=lambda ep: ep[S.OUTCOME] != "collision",
    )
    want = sorted(r[S.EPISODE_INDEX] for r in rows(episodes) if r[S.OUTCOME] != "collision")
    assert ds.episodes.tolist() == want
    assert not any(ds[i][S.COLLISION].any() for i in range(0, len(ds), 10))


def test_filter_by_index(tiny_dataset_master, cache, episodes):
    ids = [r[S.EPISODE_INDEX] for r in rows(episodes)]
    pick = [ids[-1], ids[0]]
    ds = load_windows(tiny_dataset_master, context=2, horizon=2, episodes=pick, columns=[S.ACTION], cache_dir=cache)
    assert ds.episodes.tolist() == sorted(pick)
    lengths = {r[S.EPISODE_INDEX]: r[S.LENGTH] for r in rows(episodes)}
    assert len(ds) == sum(lengths[e] - 3 for e in pick)
    np_pick = np.array(pick[:1], dtype=np.int32)
    assert select_episodes(episodes, np_pick, "train").tolist() == pick[:1]


def test_empty_filter_result_names_what_the_split_has(episodes):
    outcome = next(o for o in S.OUTCOMES if o not in {r[S.OUTCOME] for r in rows(episodes)})
    with pytest.raises(ValueError, match=rf"matches no episode of split 'train'.*{S.OUTCOME}: "):
        select_episodes(episodes, {S.OUTCOME: outcome}, "train")
    # A level the split lacks (the tiny train split has all three: take one out).
    absent = rows(episodes)[0][S.LEVEL]
    without = episodes.filter(pa.compute.not_equal(episodes.column(S.LEVEL), absent))
    present = sorted({r[S.LEVEL] for r in rows(without)})
    assert present and absent not in present
    with pytest.raises(ValueError, match=rf"matches no episode of split 'train'; it has {S.LEVEL}: {present[0]} "):
        select_episodes(without, {S.LEVEL: absent}, "train")
    with pytest.raises(ValueError, match="keeps no episode"):
        select_episodes(episodes, lambda ep: False, "train")
    with pytest.raises(ValueError, match="selects no episode"):
        select_episodes(episodes, [], "train")


def test_bad_filters_raise_with_the_fix(episodes):
    with pytest.raises(ValueError, match=r"unknown level \['experts'\]; expected one of"):
        select_episodes(episodes, {S.LEVEL: "experts"}, "train")
    with pytest.raises(ValueError, match="no episode column 'pilot'"):
        select_episodes(episodes, {"pilot": "expert"}, "train")
    with pytest.raises(ValueError, match="nested column; filter it with a callable"):
        select_episodes(episodes, {S.LIGHTING: 1}, "train")
    with pytest.raises(ValueError, match=r"episode\(s\) \[999999\] are not in split 'train'"):
        select_episodes(episodes, [999999], "train")
    with pytest.raises(TypeError, match="use a dict like"):
        select_episodes(episodes, "expert", "train")
    with pytest.raises(TypeError, match="episode_index integers"):
        select_episodes(episodes, [0.5], "train")
    with pytest.raises(ValueError, match="does not match the column type"):
        select_episodes(episodes, {S.N_OBSTACLES: "three"}, "train")


def test_an_empty_filter_through_load_windows_raises(tiny_dataset_master, cache, episodes):
    outcome = next(o for o in S.OUTCOMES if o not in {r[S.OUTCOME] for r in rows(episodes)})
    with pytest.raises(ValueError, match="matches no episode"):
        load_windows(tiny_dataset_master, episodes={S.OUTCOME: outcome}, cache_dir=cache)
