"""Usage errors: one line naming the flag, exit 2, in every orbitdata command (``cli.errors.run_app``);
failures at run time exit 1; ``--help`` and a command's own exit code are kept."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

import orbitdata
from orbitdata.cli.app import app
from orbitdata.cli.errors import run_app

runner = CliRunner()


def load_benchmark(name: str):
    """A script of benchmarks/ imported as a module (the folder is not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, Path(__file__).parents[2] / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(args: list[str], capsys, application: typer.Typer = app) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_:
        run_app(application, args)
    out = capsys.readouterr()
    return exit_.value.code, out.out, out.err


@pytest.mark.parametrize(
    "args, line",
    [
        (["--episodes", "-3"], "error: --episodes -3: must be greater than or equal to 1"),
        (["--test-fraction", "1"], "error: --test-fraction: 1 must be less than 1"),
        (["--episodes", "many"], "error: --episodes many: must be a valid integer"),
        (["--executor", "dask"], "error: --executor dask: 'dask' is not one of 'local', 'ray'"),
        (["--bogus"], "error: No such option: --bogus"),
    ],
)
def test_a_bad_flag_is_one_line_naming_it(tmp_path, capsys, args, line):
    code, out, err = run(["generate", str(tmp_path / "out"), *args], capsys)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and err.startswith(line), err
    assert err.strip().endswith("(see `orbitdata generate --help`)")
    assert "Input should" not in err and "╭" not in err and "Usage:" not in err
    assert not (tmp_path / "out").exists()


def test_more_episodes_than_a_plan_holds_is_refused_before_anything_is_written(tmp_path, capsys):
    code, out, err = run(["generate", str(tmp_path / "out"), "--episodes", "99999999999999999999"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("error: --episodes: episodes must be from 1 to 10,000,000, got 99999999999999999999"), err
    assert not (tmp_path / "out").exists()


def test_missing_arguments_and_unknown_commands(capsys):
    assert run(["generate"], capsys)[0::2] == (2, "error: Missing argument 'out' (see `orbitdata generate --help`)\n")
    code, _, err = run(["fly", "--pilot", "nobody"], capsys)
    assert code == 2 and err.startswith("error: --pilot: 'nobody' is not one of expert, risky, exploratory")
    assert run(["frob"], capsys)[0::2] == (2, "error: No such command 'frob' (see `orbitdata --help`)\n")


def test_help_and_a_commands_own_exit_code_are_kept(capsys):
    code, out, err = run(["generate", "--help"], capsys)
    assert code == 0 and "Usage: orbitdata generate" in out and err == ""
    code, out, _ = run([], capsys)  # the bare program prints its help, as before
    assert code == 2 and "Usage: orbitdata" in out
    small = typer.Typer()

    @small.command()
    def check(n: int = typer.Option(1, min=0)):
        raise typer.Exit(n)

    assert run(["--n", "3"], capsys, small)[0] == 3
    assert run(["--n", "0"], capsys, small)[0] == 0
    code, _, err = run(["--n", "-1"], capsys, small)
    assert code == 2 and err.startswith("error: --n -1: must be greater than or equal to 0 (see `")


def test_the_program_runs_through_it(tmp_path):
    paths = [str(Path(orbitdata.__file__).parents[1]), os.environ.get("PYTHONPATH", "")]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in paths if p))
    res = subprocess.run(
        [sys.executable, "-m", "orbitdata", "generate", str(tmp_path / "out"), "--episodes", "-3"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2 and res.stderr.startswith("error: --episodes -3: must be greater than or equal to 1")
    assert len(res.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "command",
    [
        ["info", "{file}"],
        ["generate", "{file}", "--episodes", "1"],
        ["validate", "{file}"],
        ["shard", "{file}"],
        ["show", "{file}", "--episode", "0", "--out", "{tmp}/x.png"],
        ["push", "{file}", "user/orbit", "--dry-run"],
    ],
)
def test_a_file_where_a_folder_belongs_exits_2_everywhere(tmp_path, command):
    f = tmp_path / "file"
    f.write_text("x")
    res = runner.invoke(app, [a.format(file=f, tmp=tmp_path) for a in command])
    assert res.exit_code == 2, res.output
    assert len(res.output.strip().splitlines()) == 1 and "Traceback" not in res.output


@pytest.mark.parametrize(
    "command",
    [
        ["info", "{tmp}"],
        ["shard", "{tmp}"],
        ["show", "{tmp}", "--episode", "0", "--out", "x.png"],
    ],
)
def test_a_folder_that_is_no_dataset_exits_2(tmp_path, command):
    res = runner.invoke(app, [a.format(tmp=tmp_path) for a in command])
    assert res.exit_code == 2, res.output
    assert len(res.output.strip().splitlines()) == 1 and "Traceback" not in res.output


@pytest.mark.parametrize(
    "args, line",
    [
        (["--json", "{tmp}"], "error: --json {tmp} is a folder: give a file's path"),
        (["--json", "{tmp}/file/grid.json"], "error: --json {tmp}/file/grid.json: {tmp}/file is a file, not a folder"),
        (["--no-render", "--video", "{tmp}/v"], "error: --video {tmp}/v records the camera: drop --no-render"),
        (["--video-format", "gif"], "error: --video-format gif without --video"),
        (["--video", "{tmp}/file"], "error: --video {tmp}/file is a file: give a folder for the videos"),
        (["--video", "{tmp}/file/v"], "error: --video {tmp}/file/v: {tmp}/file is a file, not a folder"),
        (["--image-size", "50"], "error: --image-size: image_size must be a multiple of 16"),
    ],
)
def test_fly_refuses_what_it_could_not_finish_before_flying(tmp_path, capsys, args, line):
    """A grid whose table could not be written, or whose video could not be made, is refused before
    its first episode, so no flight is lost at the end."""
    (tmp_path / "file").write_text("x")
    argv = ["fly", "--pilot", "risky", "--obstacles", "1", "--speeds", "1", "--episodes", "1"]
    code, out, err = run([*argv, *(a.format(tmp=tmp_path) for a in args)], capsys)
    assert code == 2 and out == "", err
    assert len(err.strip().splitlines()) == 1 and err.startswith(line.format(tmp=tmp_path)), err
    assert not (tmp_path / "v").exists()


def test_generate_names_the_flag_of_a_config_verdict(tmp_path, capsys):
    code, _, err = run(["generate", str(tmp_path / "g"), "--episodes", "2", "--image-size", "50"], capsys)
    assert code == 2 and err.startswith("error: --image-size: image_size must be a multiple of 16"), err
    code, _, err = run(["generate", str(tmp_path / "g"), "--ray-address", "10.0.0.1:6379"], capsys)
    assert code == 2 and err.startswith("error: --ray-address 10.0.0.1:6379 is for Ray tasks: add --executor ray"), err
    assert not (tmp_path / "g").exists()


@pytest.mark.parametrize(
    "command, line",
    [
        (["validate", "{data}", "--quick", "--json", "{tmp}"], "error: --json {tmp} is a folder"),
        (
            ["show", "{data}", "--episode", "0", "--out", "{tmp}/file/x.png"],
            "error: --out {tmp}/file/x.png: {tmp}/file",
        ),
    ],
)
def test_an_output_that_cannot_be_written_is_refused_before_the_work(
    tiny_dataset_master, tmp_path, capsys, command, line
):
    """validate used to check every file, report "valid", then fail on its --json with exit 1 (problems)."""
    (tmp_path / "file").write_text("x")
    args = [a.format(data=tiny_dataset_master, tmp=tmp_path) for a in command]
    code, out, err = run(args, capsys)
    assert code == 2 and out == "", out
    assert err.startswith(line.format(tmp=tmp_path)) and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize(
    "raised, code, line",
    [
        (FileNotFoundError("no dataset folder at /nope: give a folder made by `orbitdata generate`"), 2, "no dataset"),
        (ValueError("--k 0: give 1 or more\nmore detail"), 2, "--k 0: give 1 or more"),
        (KeyboardInterrupt(), 130, "interrupted"),
    ],
)
def test_a_script_turns_bad_input_into_one_line(capsys, raised, code, line):
    """Benchmarks and scripts run their argparse main through run_script: one line, no traceback."""
    from orbitdata.cli.errors import run_script

    def main():
        raise raised

    with pytest.raises(SystemExit) as exit_:
        run_script(main)
    err = capsys.readouterr().err
    assert exit_.value.code == code and err.count("\n") == 1 and line in err and "Traceback" not in err


def test_a_report_replaces_a_file_whole_and_writes_into_a_device_as_it_is(tmp_path):
    """fly's and validate's --json: a file is replaced whole; /dev/null (or /dev/stdout) is written
    to, never replaced by a file (as root, a rename over it would)."""
    import stat

    from orbitdata.write.parts import write_report

    report = tmp_path / "r.json"
    report.write_text("old")
    write_report(report, '{"new": 1}\n')
    assert report.read_text() == '{"new": 1}\n' and [p.name for p in tmp_path.iterdir()] == ["r.json"]
    write_report(Path("/dev/null"), "{}\n")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_an_interrupt_says_resume_only_for_a_command_that_resumes(capsys):
    """generate and push pick up their work when run again; fly, validate, info and show start over."""
    from orbitdata.cli.errors import friendly

    def interrupted():
        raise KeyboardInterrupt

    for command, says in ((friendly(resumes=True)(interrupted), " to resume"), (friendly(interrupted), "")):
        with pytest.raises(SystemExit) as exit_:
            command()
        assert exit_.value.code == 130 and capsys.readouterr().err == f"interrupted; run the same command again{says}\n"


def test_a_scripts_return_value_is_its_exit_code_and_its_help_its_first_paragraph():
    from orbitdata.cli.errors import run_script, script_help

    for returned, code in ((None, 0), (0, 0), (3, 3)):
        with pytest.raises(SystemExit) as exit_:
            run_script(lambda returned=returned: returned)
        assert exit_.value.code == code
    doc = "How often the pilots spin the body up, and why the\nfault matters.\n\n    python check_spin.py RUN\n"
    assert script_help(doc) == "How often the pilots spin the body up, and why the fault matters."


def test_a_failed_childs_reason_is_its_last_line_without_its_own_prefix():
    """bench_grid and bench_train wrap a failed child's reason in their own `error: ...` line."""
    from orbitdata.cli.errors import child_reason

    assert child_reason("progress 3/4\nerror: no dataset at /nope: give a folder\n\n", 2) == (
        "no dataset at /nope: give a folder"
    )
    assert child_reason("  \n", -9) == "exit -9"


def test_bench_grid_says_why_a_flight_failed(tmp_path):
    """A grid's flights run as child processes beside each other; one that fails is reported with
    its own reason and command, not a request to rerun it by hand."""
    import types

    bench_grid = load_benchmark("bench_grid")
    args = types.SimpleNamespace(episodes=1, seed=2, max_steps=3)
    with pytest.raises(SystemExit) as exit_:
        bench_grid.fly(tmp_path / "no-run", tmp_path / "grid.json", args, [("1", 1), ("2", 1)], batch=1)
    message = str(exit_.value)
    assert message.startswith(f"error: a flight of {tmp_path / 'no-run'} failed (")
    assert "no-run" in message.split("(", 1)[1] and "eval closed-loop" in message and "rerun" not in message


def test_estimate_tier_chain_reads_each_grids_steps_and_refuses_a_wrong_folder(tmp_path, capsys):
    """The tier chain's estimate sums frames x median step per episode, a batched step once per
    batch; a folder without the tier's results is a usage error naming it."""
    import json

    estimate = load_benchmark("estimate_tier_chain")
    episodes = [{"frames": 100, "step_ms_median": 40.0}, {"frames": 50, "step_ms_median": 80.0}]
    for batch, seconds in ((1, 8.0), (4, 2.0)):
        grid = tmp_path / f"batch{batch}.json"
        grid.write_text(json.dumps({"batch": batch, "episodes": episodes}))
        assert estimate.grid_seconds(grid) == (seconds, batch)
    assert estimate.main(["--results", str(tmp_path / "nope")]) == 2
    assert f"{tmp_path / 'nope'}/static-run is not there" in capsys.readouterr().err
    (tmp_path / "partial" / "static-run").mkdir(parents=True)
    assert estimate.main(["--results", str(tmp_path / "partial")]) == 2
    assert (
        f"{tmp_path / 'partial' / 'grid' / 'seed3' / 'planner-imagined.json'} is not there" in capsys.readouterr().err
    )


def test_the_tier_chain_estimate_counts_the_grids_the_chain_flies():
    """``estimate_tier_chain.EVERY_SEED`` copies the grids that ``TIER=dynamic`` flies on every seed
    from scripts/reproduce_model.sh (those it spawns two at a time; the expert's and the Diffusion
    Policy's, which record no control-step times, are left out of both): a grid added to (or dropped
    from) the chain must be added to (or dropped from) the estimate, or it silently under- or
    over-counts."""
    import re

    estimate = load_benchmark("estimate_tier_chain")
    script = (Path(__file__).parents[2] / "scripts" / "reproduce_model.sh").read_text()
    dynamic = script.split('if [ "${TIER:-static}" = dynamic ]; then', 1)[1]
    tier, static_run = dynamic.split('SRUN="$OUT/wm-cpu-step5"', 1)
    static_run = static_run.split('mkdir -p "$SDIR/test"', 1)[0]
    flown = {("grid", name) for name in re.findall(r"spawn fly_model (\S+)", tier)}
    validation_only = set()
    for line in static_run.splitlines():
        named = re.search(r'spawn fly_run "\$SRUN" (\S+)|spawn fly "\$GDIR/([^"]+)\.json"', line)
        if named:
            grid = ("static-run", named.group(1) or named.group(2))
            (validation_only if '"$seed" -gt 2 ] ||' in line else flown).add(grid)
    # each K's grid is flown as two halves and merged: one name per K in the loop
    ks = re.search(r"^\s*for k in ([\d ]+); do$", static_run, re.M).group(1).split()
    stem = re.search(r"^\s*KN=(\S+)\$k$", static_run, re.M).group(1)
    halves = ("static-run", '"$KN-speed$speed"')
    assert halves in flown and ks, "the chain no longer flies each K's grid as two halves: update this test"
    flown = (flown - {halves}) | {("static-run", stem + k) for k in ks}
    assert flown == set(estimate.EVERY_SEED) and len(estimate.EVERY_SEED) == len(flown)
    assert validation_only == {estimate.VALIDATION_ONLY}
    # and the test seeds pool every grid flown on every seed: the tier's (with its planner.json, the
    # expert's and the policy's) and the static run's (LOSSES)
    pooled = re.search(r"for pilot in (.*?); do", tier, re.S).group(1).replace("\\\n", " ")
    pooled = set(re.sub(r"\$\(.*?\)", " ", pooled).split())
    assert pooled == {p for f, p in flown if f == "grid"} | {"planner", "expert"}
    losses = re.search(r"LOSSES=\((.*?)\)", dynamic, re.S).group(1).split()
    assert sorted(losses) == sorted(p for f, p in flown if f == "static-run")


def closed_port() -> int:
    """A local port nothing listens on (bound, then let go)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_ray_address_where_no_cluster_answers_is_refused_at_once_writing_nothing(tmp_path, capsys, monkeypatch):
    """ray.init retries a dead address for minutes; the check answers in seconds."""
    from orbitdata.write.executors import check_ray_address

    address = f"127.0.0.1:{closed_port()}"
    code, _, err = run(
        ["generate", str(tmp_path / "out"), "--episodes", "2", "--executor", "ray", "--ray-address", address], capsys
    )
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"error: --ray-address {address}: no Ray cluster answers there ("), err
    assert not (tmp_path / "out").exists()
    monkeypatch.setenv("RAY_ADDRESS", f"ray://{address}")
    with pytest.raises(ValueError, match=f"RAY_ADDRESS ray://{address}: no Ray cluster answers there"):
        check_ray_address(None)
    for left_to_ray in ("auto", "local", ""):
        check_ray_address(left_to_ray)


def test_a_full_disk_names_the_file_and_the_way_back_leaving_no_temporary(tmp_path, capsys, monkeypatch):
    import errno

    from orbitdata.write import parts

    fsync, calls = parts.os.fsync, []

    def full_after_the_manifest(fd):
        calls.append(fd)
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        fsync(fd)

    monkeypatch.setattr(parts.os, "fsync", full_after_the_manifest)
    out = tmp_path / "out"
    args = ["generate", str(out), "--episodes", "2", "--image-size", "16", "--workers", "1"]
    code, _, err = run(args, capsys)
    assert code == 1 and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"error: No space left on device while writing {out / 'parts'}/"), err
    assert err.strip().endswith("free some space there, then run the same command again to resume"), err
    assert not list(out.rglob(".tmp-*"))

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(parts.os, "fsync", full)
    code, _, err = run(args, capsys)  # full from the first file on: the manifest's
    assert code == 2 and err.startswith(
        f"error: cannot write to {out} (No space left on device); choose another OUT or free some space there"
    ), err
