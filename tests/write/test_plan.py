"""The episode plan: deterministic, stratified by level, independent of workers."""

from orbitdata.config import DatasetConfig
from orbitdata.write.plan import plan_episodes, plan_units


def test_paper_split_is_7200_800_stratified_by_level():
    tasks = plan_episodes(DatasetConfig())
    assert len(tasks) == 8000
    test = [t for t in tasks if t.split == "test"]
    assert len(test) == 800
    for level, share in zip(("expert", "risky", "exploratory"), (0.5, 0.25, 0.25)):
        n = sum(t.level == level for t in tasks)
        assert n == 8000 * share
        assert sum(t.level == level for t in test) == round(n * 0.1)
    assert len({t.seed for t in tasks}) == 8000


def test_plan_is_a_pure_function_of_the_config():
    a = plan_episodes(DatasetConfig(episodes=50, seed=3))
    assert a == plan_episodes(DatasetConfig(episodes=50, seed=3))
    assert a != plan_episodes(DatasetConfig(episodes=50, seed=4))
    units = plan_units(DatasetConfig(episodes=50, seed=3, episodes_per_unit=8))
    assert [t for u in units for t in u.episodes] == a
    assert [len(u.episodes) for u in units] == [8] * 6 + [2]
