"""`generate` + `shard`: plain-HF loading, readers, counts, determinism and crash safety."""

import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml
from tiny import dynamic_config, tiny_config

from orbitdata import schema as S
from orbitdata.viz import overview_figure
from orbitdata.write.finalize import finalize
from orbitdata.write.generate import generate


def tree_digest(root: Path) -> dict:
    """sha256 of every file under root (relative path -> digest)."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def card_yaml(root: Path) -> dict:
    text = (root / S.CARD_PATH).read_text()
    return yaml.safe_load(text.split("---")[1])


def test_layout_matches_the_contract(tiny_dataset_master):
    files = set(tree_digest(tiny_dataset_master))
    assert {"README.md", "meta/info.json", "meta/stats.json"} <= files
    shards = [f for f in files if f.startswith(("data/", "episodes/"))]
    assert shards and all(S.SHARD_RE.match(f) for f in shards)
    assert not any(f.startswith("parts") or "/.tmp" in f for f in files)


def test_load_dataset_with_no_custom_code(tiny_dataset_master):
    from datasets import load_dataset

    info = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())
    steps = load_dataset(str(tiny_dataset_master), split="train")
    assert steps.num_rows == info["counts"]["splits"]["train"]["frames"]
    row = steps[0]
    assert row[S.IMAGE].size == (64, 64) and row[S.IMAGE].mode == "RGB"
    assert row[S.DEPTH].size == (64, 64)
    assert len(row[S.STATE]) == 16 and len(row[S.ACTION]) == 8 and len(row[S.DEPTH_LOW]) == 256
    episodes = load_dataset(str(tiny_dataset_master), "episodes", split="test")
    assert episodes.num_rows == info["counts"]["splits"]["test"]["episodes"]
    assert set(episodes[S.SPLIT]) == {"test"}


def test_pyarrow_polars_and_duckdb_read_every_file(tiny_dataset_master):
    import duckdb
    import polars as pl

    for path in sorted(tiny_dataset_master.glob("*/*.parquet")):
        n = pq.read_table(path).num_rows
        assert pl.read_parquet(path).height == n
        assert duckdb.sql(f"select count(*) from '{path}'").fetchall()[0][0] == n
    # Column names with dots work in SQL when quoted.
    frames = duckdb.sql(
        f"select count(*) from '{tiny_dataset_master}/data/*.parquet' where \"{S.IS_LAST}\""
    ).fetchall()[0][0]
    episodes = duckdb.sql(f"select count(*) from '{tiny_dataset_master}/episodes/*.parquet'").fetchall()[0][0]
    assert frames == episodes == 6


def test_counts_agree_between_card_info_and_data(tiny_dataset_master):
    info = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())
    card = card_yaml(tiny_dataset_master)
    data = {s: 0 for s in S.SPLITS}
    for path in tiny_dataset_master.glob("data/*.parquet"):
        data[path.name.split("-")[0]] += pq.read_metadata(path).num_rows
    episodes = {s: 0 for s in S.SPLITS}
    for path in tiny_dataset_master.glob("episodes/*.parquet"):
        t = pq.read_table(path)
        episodes[path.name.split("-")[0]] += t.num_rows
        assert sum(t.column(S.LENGTH).to_pylist()) == data[path.name.split("-")[0]]
    card_counts = {c["config_name"]: {s["name"]: s["num_examples"] for s in c["splits"]} for c in card["dataset_info"]}
    for split, counts in info["counts"]["splits"].items():
        assert counts["frames"] == data[split] == card_counts["default"][split]
        assert counts["episodes"] == episodes[split] == card_counts["episodes"][split]
    assert info["counts"]["episodes"] == 6
    text = (tiny_dataset_master / S.CARD_PATH).read_text()
    assert f"{info['counts']['frames']} frames" in text


def test_info_records_config_hashes_and_stats(tiny_dataset_master):
    from orbitdata.config import GenerationConfig
    from orbitdata.info import sha256_file

    info = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())
    assert info["schema_version"] == S.SCHEMA_VERSION and info["fps"] == 25
    assert GenerationConfig.from_dict(info["config"]) == tiny_config()
    on_disk = {str(p.relative_to(tiny_dataset_master)) for p in tiny_dataset_master.rglob("*") if p.is_file()}
    assert set(info["files"]) == on_disk - {S.INFO_PATH}
    for rel, meta in info["files"].items():
        assert sha256_file(tiny_dataset_master / rel) == meta["sha256"]
    stats = json.loads((tiny_dataset_master / S.STATS_PATH).read_text())
    for name in (S.STATE, S.ACTION, S.DEPTH_LOW, S.MIN_CLEARANCE, S.IMAGE):
        assert {"mean", "std", "min", "max", "q01", "q99", "count"} <= set(stats[name])
    assert len(stats[S.STATE]["mean"]) == 16
    assert stats[S.STATE]["count"] == info["counts"]["splits"]["train"]["frames"]


def test_episode_rows_point_at_their_frames(tiny_dataset_master):
    for path in tiny_dataset_master.glob("episodes/*.parquet"):
        for ep in pq.read_table(path).to_pylist():
            frames = pq.read_table(tiny_dataset_master / ep[S.DATA_FILE]).slice(
                ep[S.ROW_START], ep[S.ROW_END] - ep[S.ROW_START]
            )
            assert frames.num_rows == ep[S.LENGTH]
            assert set(frames.column(S.EPISODE_INDEX).to_pylist()) == {ep[S.EPISODE_INDEX]}
            assert frames.column(S.FRAME_INDEX).to_pylist() == list(range(ep[S.LENGTH]))
            is_last = frames.column(S.IS_LAST).to_pylist()
            assert is_last[-1] and not any(is_last[:-1])


def test_workers_one_and_two_give_identical_bytes(tiny_dataset_master, tmp_path):
    out = tmp_path / "two" / "orbit"  # same folder name: the card mentions it
    generate(out, tiny_config(), workers=2, figure=overview_figure)
    assert tree_digest(out) == tree_digest(tiny_dataset_master)


def test_ray_executor_gives_identical_bytes(tiny_dataset_master, tmp_path):
    import ray  # noqa: F401  the test extra installs it: a broken import fails here, it is not skipped

    out = tmp_path / "ray" / "orbit"
    generate(out, tiny_config(), workers=2, executor="ray", figure=overview_figure)
    assert tree_digest(out) == tree_digest(tiny_dataset_master)


# Dies by SIGKILL in the middle of writing the third unit: its frames are on disk, its episode
# rows (the mark of a finished unit) are not. Deterministic: no polling, no timing.
# argv: OUT and the name of the config's maker in tests/tiny.py (one per tier).
KILL_SCRIPT = """
import os, signal, sys
import tiny
from orbitdata.write import parts
from orbitdata.write.generate import generate

write_unit, done = parts.write_unit, []


def write_unit_or_die(out, name, steps, episodes):
    if len(done) == 2:
        parts.atomic_write(parts.steps_part(out, name), steps)
        os.kill(os.getpid(), signal.SIGKILL)
    write_unit(out, name, steps, episodes)
    done.append(name)


parts.write_unit = write_unit_or_die
generate(sys.argv[1], getattr(tiny, sys.argv[2])(episodes_per_unit=1), workers=1)
"""


@pytest.mark.parametrize("make", [tiny_config, dynamic_config], ids=["static", "dynamic"])
def test_sigkill_then_resume_equals_an_uninterrupted_run_and_redoes_a_damaged_part(tmp_path, make):
    clean = tmp_path / "clean" / "orbit"
    generate(clean, make(episodes_per_unit=1), workers=1, figure=overview_figure)
    out = tmp_path / "killed" / "orbit"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).parents[1]))  # tests/, for tiny.py
    proc = subprocess.run([sys.executable, "-c", KILL_SCRIPT, str(out), make.__name__], env=env, timeout=300)
    assert proc.returncode == -signal.SIGKILL
    assert len(list((out / "parts").glob("*.episodes.parquet"))) == 2  # two whole units
    assert len(list((out / "parts").glob("*.steps.parquet"))) == 3  # and the frames of a third
    assert not (out / S.INFO_PATH).exists()
    # A part file cut short after the fact (a copy, a disk error) is found and its unit redone.
    cut = sorted((out / "parts").glob("*.steps.parquet"))[0]
    cut.write_bytes(cut.read_bytes()[:100])
    notices = []
    generate(out, make(episodes_per_unit=1), workers=1, figure=overview_figure, notice=notices.append)  # resume
    assert notices == [f"{cut} is damaged (Parquet cannot open it): its unit is generated again"]
    assert tree_digest(out) == tree_digest(clean)


def test_a_complete_dataset_is_not_regenerated(tiny_dataset, monkeypatch):
    before = tree_digest(tiny_dataset)
    import orbitdata.write.generate as gen

    monkeypatch.setattr(gen, "run_local", lambda *a, **k: pytest.fail("nothing should be flown"))
    generate(tiny_dataset, tiny_config(), workers=1)
    assert tree_digest(tiny_dataset) == before


def test_reshard_into_smaller_files_keeps_every_row(tiny_dataset):
    info = finalize(tiny_dataset, max_shard_bytes=50_000, figure=overview_figure)
    train = sorted(tiny_dataset.glob("data/train-*.parquet"))
    assert len(train) > 1 and all(S.SHARD_RE.match(f"data/{p.name}") for p in train)
    assert info.counts["frames"] == sum(pq.read_metadata(p).num_rows for p in tiny_dataset.glob("data/*.parquet"))
    from datasets import load_dataset

    assert load_dataset(str(tiny_dataset), split="train").num_rows == info.counts["splits"]["train"]["frames"]


def test_reshard_round_trip_reproduces_the_generated_bytes(tiny_dataset, tiny_dataset_master):
    """Shard bytes depend on the rows alone, not on whether they came from parts or shards."""
    finalize(tiny_dataset, max_shard_bytes=50_000, figure=overview_figure)
    assert tree_digest(tiny_dataset) != tree_digest(tiny_dataset_master)
    finalize(tiny_dataset, max_shard_bytes=500_000_000, figure=overview_figure)
    assert tree_digest(tiny_dataset) == tree_digest(tiny_dataset_master)


def test_a_reshard_refuses_data_its_episodes_tables_do_not_list_and_keeps_every_shard(tiny_dataset):
    """A missing episodes table (a partial download, a deleted file) would have made the re-shard skip
    its split and delete that split's data shards."""
    before = tree_digest(tiny_dataset)
    (test_table,) = tiny_dataset.glob("episodes/test-*.parquet")
    test_table.unlink()
    with pytest.raises(ValueError, match=r"1 test data shard\(s\) and no episode of them in episodes/; restore"):
        finalize(tiny_dataset)
    del before[str(test_table.relative_to(tiny_dataset))]
    assert tree_digest(tiny_dataset) == before


def test_a_reshard_cut_before_it_removed_the_old_layout_is_finished_by_running_it_again(
    tiny_dataset, tiny_dataset_master
):
    """The new shards are renamed into place before the episodes table is, and the old ones go last:
    shards of another layout that no table names are leftovers, and the rerun ends as if never cut."""
    import shutil

    (train,) = tiny_dataset.glob("data/train-*.parquet")
    for index in range(2):  # as a cut re-shard into two files leaves them
        shutil.copy(train, tiny_dataset / S.shard_path(S.DATA_DIR, "train", index, 2))
    finalize(tiny_dataset, figure=overview_figure)
    assert tree_digest(tiny_dataset) == tree_digest(tiny_dataset_master)


def test_a_reshard_refuses_an_episodes_table_that_points_at_other_frames(tiny_dataset):
    """As a re-shard cut between replacing the data shards and their episodes table leaves it."""
    (table_path,) = tiny_dataset.glob("episodes/train-*.parquet")
    table = pq.read_table(table_path)
    rows = table.to_pylist()
    assert len(rows) >= 2
    rows[0][S.ROW_START], rows[0][S.ROW_END] = rows[1][S.ROW_START], rows[1][S.ROW_END]
    pq.write_table(type(table).from_pylist(rows, schema=table.schema), table_path)
    before = tree_digest(tiny_dataset)
    with pytest.raises(ValueError, match="which hold other frames"):
        finalize(tiny_dataset)
    assert tree_digest(tiny_dataset) == before


def test_parts_left_by_a_kill_while_a_finished_generation_removed_them_are_not_resharded(
    tmp_path, tiny_dataset_master, monkeypatch
):
    """info.json is written last, then the parts are removed: `orbitdata shard` after a kill there
    keeps the finished shards (it used to rebuild them from the parts that survived, smaller)."""
    import shutil

    from orbitdata.write import finalize as finalizing
    from orbitdata.write import parts

    out, rmtree = tmp_path / "orbit", shutil.rmtree

    def killed_midway(path, *args, **kwargs):
        if Path(path) == parts.parts_dir(out):
            for part in sorted(parts.parts_dir(out).glob("unit-*.parquet"))[:2]:  # one unit's two files
                part.unlink()
            raise KeyboardInterrupt
        return rmtree(path, *args, **kwargs)

    monkeypatch.setattr(finalizing.shutil, "rmtree", killed_midway)
    with pytest.raises(KeyboardInterrupt):
        generate(out, tiny_config(), workers=1, figure=overview_figure)
    monkeypatch.setattr(finalizing.shutil, "rmtree", rmtree)
    assert (out / S.INFO_PATH).exists() and any(parts.parts_dir(out).glob("unit-*.parquet"))
    finalize(out, figure=overview_figure)  # what `orbitdata shard OUT` runs
    assert not parts.parts_dir(out).exists()
    assert tree_digest(out) == tree_digest(tiny_dataset_master)


def test_generate_from_python_refuses_what_it_cannot_run(tmp_path):
    for kwargs, says in (
        (dict(config=None), "config is a NoneType: give a GenerationConfig"),
        (dict(config=tiny_config(2), workers=0), "workers=0: give 1 or more processes"),
        (dict(config=tiny_config(2), workers=-1), "workers=-1: give 1 or more processes"),
    ):
        with pytest.raises(ValueError, match=says):
            generate(tmp_path / "out", **kwargs)
    assert not (tmp_path / "out").exists()


def _children(pid: int) -> set[int]:
    found = set()
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            fields = dict(line.split(":\t", 1) for line in status.read_text().splitlines() if ":\t" in line)
        except OSError:
            continue
        if fields.get("PPid", "").strip() == str(pid):
            found.add(int(status.parent.name))
    return found


def _read(path: str) -> str:
    try:
        return Path(path).read_text()
    except OSError:  # the process ended meanwhile
        return ""


def _alive(pids: set[int]) -> set[int]:
    return {p for p in pids if _read(f"/proc/{p}/status") and "State:\tZ" not in _read(f"/proc/{p}/status")}


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc to find the workers")
@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGKILL])
def test_a_killed_generate_leaves_no_worker_behind(tmp_path, how):
    """SIGTERM stops `generate` as Ctrl-C does; after SIGKILL its workers end with it."""
    import time

    command = [sys.executable, "-m", "orbitdata", "generate", str(tmp_path / "out"), "--episodes", "60"]
    proc = subprocess.Popen([*command, "--image-size", "32", "--workers", "2"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    workers: set[int] = set()
    while time.monotonic() < deadline and not (tmp_path / "out" / "parts").is_dir():
        time.sleep(0.2)
    while time.monotonic() < deadline and len(workers) < 2:
        workers |= {p for p in _children(proc.pid) if "spawn_main" in _read(f"/proc/{p}/cmdline")}
        time.sleep(0.2)
    assert len(workers) >= 2, "the workers never started"
    proc.send_signal(how)
    proc.wait(timeout=60)
    end = time.monotonic() + 30
    while _alive(workers) and time.monotonic() < end:
        time.sleep(0.2)
    assert not _alive(workers), f"workers {sorted(_alive(workers))} outlived generate"
    if how == signal.SIGTERM:
        assert "interrupted; run the same command again to resume" in proc.stderr.read()
