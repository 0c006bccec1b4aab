"""`orbitdata generate` / `shard` flags and errors."""

import json
import os
import subprocess
from pathlib import Path

import pytest
from typer.testing import CliRunner

from orbitdata.cli.app import app

runner = CliRunner()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--episodes", "0"], "--episodes"),
        (["--test-fraction", "1.5"], "--test-fraction"),
        (["--image-size", "100"], "multiple of 16"),
        (["--executor", "dask"], "--executor"),
        (["--workers", "-1"], "--workers"),
        (["--seed", "-5"], "--seed"),
        (["--max-shard-mb", "0"], "--max-shard-mb"),
    ],
)
def test_bad_flags(tmp_path, args, message):
    res = runner.invoke(app, ["generate", str(tmp_path / "out"), *args])
    assert res.exit_code == 2, res.output
    assert message in res.output and "Traceback" not in res.output
    assert not (tmp_path / "out").exists()


def test_config_file_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\nn_obstacles = [1, 5]\nbogus = 3\n")
    res = runner.invoke(app, ["generate", str(tmp_path / "out"), "--config", str(bad)])
    assert res.exit_code == 2 and "bogus" in res.output and "unknown setting" in res.output
    res = runner.invoke(app, ["generate", str(tmp_path / "out"), "--config", str(tmp_path / "missing.toml")])
    assert res.exit_code == 2 and "does not exist" in res.output
    for setting, says in (
        ('[sim]\ndt = "fast"', "sim.dt: expected a number, got 'fast'"),
        ("[scenario]\nmax_tries = 1.5", "scenario.max_tries: expected a whole number, got 1.5"),
        ('[dataset]\nepisodes = "10"', "dataset.episodes: expected a whole number, got '10'"),
        ("[dataset]\nepisodes = true", "dataset.episodes: expected a whole number, got True"),
        (
            '[dataset]\ncompression = "lz5"',
            "compression must be a Parquet codec (brotli, gzip, lz4, lz4_raw, none, snappy",
        ),
        ("[dataset]\npng_compression = 42", "png_compression must be in [0, 9], got 42"),
    ):
        bad.write_text(setting + "\n")
        res = runner.invoke(app, ["generate", str(tmp_path / "out"), "--config", str(bad)])
        assert res.exit_code == 2 and says in res.output and len(res.output.strip().splitlines()) == 1, res.output
    bad.write_bytes(b"[dataset]\nepisodes = 4 # \xff\n")
    for config, says in ((bad, "is not UTF-8 text"), (tmp_path, "is a folder")):
        res = runner.invoke(app, ["generate", str(tmp_path / "out"), "--config", str(config)])
        assert res.exit_code == 2 and f"config file {config} {says}" in res.output, res.output
    assert not (tmp_path / "out").exists()


def test_a_sim_dt_other_than_the_schemas_is_refused(tmp_path):
    from orbitdata.sim.config import SimConfig

    with pytest.raises(ValueError, match="sim.dt must be 0.04 s"):
        SimConfig(dt=0.02)
    assert SimConfig(dt=0.04).dt == 0.04  # written out in a TOML, 0.04 is the same number
    toml = tmp_path / "fast.toml"
    toml.write_text("[sim]\ndt = 0.02\n")
    res = runner.invoke(app, ["generate", str(tmp_path / "out"), "--config", str(toml)])
    assert res.exit_code == 2 and "sim.dt must be 0.04 s" in res.output
    assert not (tmp_path / "out").exists()


@pytest.fixture
def unwritable_dir(tmp_path):
    """A folder nobody may write into, root included (CI runs as root)."""
    folder = tmp_path / "ro"
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o500)
        yield folder
        folder.chmod(0o700)
    elif subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode == 0:
        yield folder  # immutable: even root cannot create entries
        subprocess.run(["chattr", "-i", str(folder)], check=True)
    else:
        yield Path("/sys")  # sysfs refuses new entries to everyone


def test_unwritable_out(unwritable_dir):
    out = unwritable_dir / "out"
    res = runner.invoke(app, ["generate", str(out), "--episodes", "1", "--image-size", "32"])
    assert res.exit_code == 2, res.output  # a usage error: OUT is a bad path
    assert f"cannot write to {out}" in res.output and "choose another OUT" in res.output
    assert "Traceback" not in res.output
    assert not out.exists()


def test_out_that_is_a_file(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    res = runner.invoke(app, ["generate", str(f), "--episodes", "1", "--image-size", "32"])
    assert res.exit_code == 2 and "not a folder" in res.output


def test_config_clash_needs_overwrite(tiny_dataset):
    args = ["generate", str(tiny_dataset), "--episodes", "3", "--image-size", "64", "--workers", "1"]
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and "another config (dataset.episodes: " in res.output and "--overwrite" in res.output
    assert (tiny_dataset / "meta" / "info.json").exists()  # nothing was touched


def test_overwrite_replaces_the_dataset_and_keeps_the_users_files(tiny_dataset):
    """--overwrite removes what orbitdata wrote there, not a file of the user's beside it."""
    mine = [
        tiny_dataset / "meta" / "notes.md",
        tiny_dataset / "episodes" / "labels.csv",
        tiny_dataset / "data" / "x.txt",
    ]
    for path in mine:
        path.write_text("mine")
    args = ["generate", str(tiny_dataset), "--episodes", "2", "--image-size", "32", "--workers", "1", "--overwrite"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    assert all(path.read_text() == "mine" for path in mine)
    assert json.loads((tiny_dataset / "meta" / "info.json").read_text())["config"]["dataset"]["episodes"] == 2


def test_non_dataset_folder_is_not_clobbered(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("precious")
    res = runner.invoke(app, ["generate", str(out), "--episodes", "1", "--image-size", "32"])
    assert res.exit_code == 2 and "not empty" in res.output
    assert (out / "thesis.tex").read_text() == "precious"


def test_generate_from_toml_and_flags(tmp_path):
    cfg = tmp_path / "small.toml"
    cfg.write_text(
        "[dataset]\nlevel_mix = [0.0, 1.0, 0.0]\n[scenario]\nn_obstacles = [5, 5]\n[sim.camera]\nimage_size = 32\n"
    )
    out = tmp_path / "out"
    res = runner.invoke(
        app, ["generate", str(out), "--config", str(cfg), "--episodes", "2", "--workers", "1", "--test-fraction", "0"]
    )
    assert res.exit_code == 0, res.output
    import json

    info = json.loads((out / "meta/info.json").read_text())
    assert info["config"]["scenario"]["n_obstacles"] == [5, 5]
    assert info["counts"]["splits"]["train"]["levels"]["risky"]["episodes"] == 2
    assert "test" not in info["counts"]["splits"]


def test_a_single_episode_says_in_one_line_that_there_is_no_test_split(tmp_path):
    cfg = tmp_path / "risky.toml"
    cfg.write_text("[dataset]\nlevel_mix = [0.0, 1.0, 0.0]\n[sim.camera]\nimage_size = 32\n")
    res = runner.invoke(
        app, ["generate", str(tmp_path / "one"), "--config", str(cfg), "--episodes", "1", "--workers", "1"]
    )
    assert res.exit_code == 0, res.output
    notes = [line for line in res.output.splitlines() if "test split" in line]
    assert notes == ["note: no test split: one episode is all train; pass --episodes 2 or more for a test split"]


def test_shard_refuses_an_unfinished_generation(tmp_path):
    """Compacting the parts of an interrupted run would make a smaller dataset that the original
    command then never finishes: shard says to finish it instead."""
    from tiny import tiny_config

    from orbitdata.write.generate import prepare_output

    out = tmp_path / "cut"
    prepare_output(out, tiny_config(4), overwrite=False)  # the manifest, as a run killed before its first part
    res = runner.invoke(app, ["shard", str(out)])
    assert res.exit_code == 2 and "unfinished generation (0 of 4 episodes)" in res.output, res.output
    assert not (out / "meta" / "info.json").exists()


def test_the_cards_repo_id_survives_a_reshard(tmp_path, monkeypatch):
    out = tmp_path / "orbit"
    args = ["generate", str(out), "--episodes", "2", "--image-size", "32", "--workers", "1", "--repo-id", "me/orbit"]
    assert runner.invoke(app, args).exit_code == 0
    card = out / "README.md"
    card.write_text('Compare with `load_dataset("other/benchmark")`.\n' + card.read_text())  # an edit of the user's
    assert runner.invoke(app, ["shard", str(out), "--max-shard-mb", "1"]).exit_code == 0
    assert 'load_dataset("me/orbit", split="train")' in card.read_text()
    assert runner.invoke(app, ["shard", str(out), "--repo-id", "me/orbit-v2"]).exit_code == 0
    assert 'load_dataset("me/orbit-v2", split="train")' in card.read_text()  # named for the push to come
    monkeypatch.chdir(tmp_path / "orbit")
    (tmp_path / "orbit" / "README.md").unlink()
    assert runner.invoke(app, ["shard", "."]).exit_code == 0
    assert 'load_dataset("orbit", split="train")' in (out / "README.md").read_text()  # not load_dataset("")


def test_generating_a_finished_dataset_again_says_there_is_nothing_to_do(tmp_path):
    out = tmp_path / "orbit"
    args = ["generate", str(out), "--episodes", "2", "--image-size", "32", "--workers", "1"]
    first = runner.invoke(app, args)
    assert first.exit_code == 0 and "wrote 2 episodes" in first.output, first.output
    again = runner.invoke(app, args)
    assert again.exit_code == 0 and "holds these 2 episodes already" in again.output and "wrote" not in again.output
