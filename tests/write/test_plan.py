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


def _digest(cfg: DatasetConfig) -> str:
    import hashlib

    return hashlib.sha256(repr([(t.index, t.split, t.level, t.seed) for t in plan_episodes(cfg)]).encode()).hexdigest()


def test_a_small_dataset_keeps_one_test_episode():
    """Too few episodes for any level's share to round to one: one test episode all the same."""
    for n in range(2, 12):  # 0 test episodes each before, at the default share of 0.1
        tasks = plan_episodes(DatasetConfig(episodes=n))
        assert sum(t.split == "test" for t in tasks) == 1, n
    assert all(t.split == "train" for t in plan_episodes(DatasetConfig(episodes=1)))  # nothing left to train on
    assert all(t.split == "train" for t in plan_episodes(DatasetConfig(episodes=5, test_fraction=0.0)))


def test_a_test_share_that_takes_every_episode_leaves_one_to_train_on():
    for n, share in ((1, 0.99), (3, 0.99), (3, 0.9), (10, 0.99)):
        splits = [t.split for t in plan_episodes(DatasetConfig(episodes=n, test_fraction=share))]
        assert splits.count("train") == 1 and splits.count("test") == n - 1, (n, share)


def test_plans_with_a_test_share_are_unchanged():
    """The default 8000-episode plan and the golden tiny dataset's, as the code made them before
    small datasets kept a test episode (digests of (index, split, level, seed))."""
    assert _digest(DatasetConfig()) == "6cee97857c71d48d4c3e3ceefdd58d16baf1c03a58d10483b9238e076b763dec"
    assert (
        _digest(DatasetConfig(episodes=6, test_fraction=0.34))
        == "22b0c5cfea03ff925365508be1c03b245e586a7114bd938664db8ce30066554d"
    )
