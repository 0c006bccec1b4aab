"""How validation runs and reports: CLI exit codes, JSON, caps, workers, seams, Hub snapshots."""

from __future__ import annotations

import json

import corruptions as X
import numpy as np
import pytest
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitdata.cli.app import app
from orbitdata.validate import ValidateOptions, validate
from orbitdata.validate import checks as C

runner = CliRunner()


def test_cli_clean_exits_0_and_writes_json(tiny_dataset_master, tmp_path):
    out = tmp_path / "report.json"
    result = runner.invoke(app, ["validate", str(tiny_dataset_master), "--workers", "1", "--json", str(out)])
    assert result.exit_code == 0, result.output
    assert "valid: no problems found" in result.output
    report = json.loads(out.read_text())
    assert report["ok"] is True and report["mode"] == "full"
    assert {c["name"] for c in report["checks"]} == {c.name for c in C.CHECKS}
    assert all(c["status"] == "pass" for c in report["checks"])
    assert report["checked"]["frames"] > 0 and report["checked"]["frames_per_s"] > 0


def test_cli_problems_exit_1_with_readable_report(tiny_dataset, tmp_path):
    ep = X.longest_train_episode(tiny_dataset)
    X.edit_state(tiny_dataset, X.TRAIN, ep[S.ROW_START] + 5, lambda s: s.__setitem__(1, s[1] + 0.1))
    out = tmp_path / "report.json"
    result = runner.invoke(app, ["validate", str(tiny_dataset), "--workers", "1", "--json", str(out)])
    assert result.exit_code == 1, result.output
    assert "FAIL  kinematics.position" in result.output
    assert f"{X.TRAIN} episode {ep[S.EPISODE_INDEX]} frame 5:" in result.output
    assert result.output.rstrip().splitlines()[-2].startswith("INVALID")
    report = json.loads(out.read_text())
    assert report["ok"] is False and "kinematics.position" in report["failed_checks"]
    entry = next(c for c in report["checks"] if c["name"] == C.KIN_POSITION)
    assert entry["status"] == "fail" and entry["findings"][0]["file"] == X.TRAIN
    assert {f["frame"] for f in entry["findings"]} >= {5, 6}


@pytest.mark.parametrize("args", [["/definitely/not/here"], ["--workers", "-1"], ["--max-per-check", "0"]])
def test_cli_usage_errors_exit_2(tiny_dataset_master, args):
    argv = ["validate", *args] if args[0].startswith("/") else ["validate", str(tiny_dataset_master), *args]
    result = runner.invoke(app, argv)
    assert result.exit_code == 2, result.output


def test_cli_file_instead_of_folder_exits_2(tiny_dataset_master):
    result = runner.invoke(app, ["validate", str(tiny_dataset_master / S.INFO_PATH)])
    assert result.exit_code == 2 and "not a dataset folder" in result.output


def test_cli_folder_that_is_no_dataset_exits_2(tmp_path):
    (tmp_path / "config.json").write_text("{}")  # a run folder, say
    result = runner.invoke(app, ["validate", str(tmp_path)])
    assert result.exit_code == 2 and "is not an orbitdata dataset" in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_quick_mode_skips_row_checks(tiny_dataset):
    ep = X.longest_train_episode(tiny_dataset)
    X.edit_state(tiny_dataset, X.TRAIN, ep[S.ROW_START] + 5, lambda s: s.__setitem__(4, np.nan))
    quick = validate(tiny_dataset, ValidateOptions(quick=True, workers=1))
    assert quick.ok and quick.mode == "quick"
    assert quick.status(C.FINITE) == "skip" and quick.status(C.SHA256) == "pass"
    assert "skip  values.finite" in quick.render()
    assert C.FINITE in validate(tiny_dataset, ValidateOptions(workers=1)).failed()


def test_findings_are_capped_but_counted(tiny_dataset):
    table = X.read(tiny_dataset, X.TEST)
    ts = X.scalars(table, S.TIMESTAMP) + 0.01  # every row off the grid
    X.write(tiny_dataset, X.TEST, X.set_scalar(table, S.TIMESTAMP, ts))
    report = validate(tiny_dataset, ValidateOptions(workers=1, max_per_check=3))
    assert report.sink.counts[C.TIMESTAMPS] == table.num_rows
    assert len(report.findings(C.TIMESTAMPS)) == 3
    assert f"... and {table.num_rows - 3} more" in report.render()


def test_seam_between_row_groups_is_checked(tiny_dataset):
    """Fuel rises exactly across the row-group boundary at row 64: only the seam sees it."""
    ep = X.episode(tiny_dataset, 1)
    assert ep[S.ROW_START] < X.ROW_GROUP_ROWS < ep[S.ROW_END]
    table = X.read(tiny_dataset, X.TRAIN)
    state = X.matrix(table, S.STATE, S.STATE_DIM)
    state[X.ROW_GROUP_ROWS, 15] = state[X.ROW_GROUP_ROWS - 1, 15] + 1e-4
    X.write(tiny_dataset, X.TRAIN, X.set_matrix(table, S.STATE, state))
    frame = X.ROW_GROUP_ROWS - ep[S.ROW_START]
    for workers in (1, 2):
        report = validate(tiny_dataset, ValidateOptions(workers=workers))
        assert [(f.episode, f.frame) for f in report.findings(C.FUEL)] == [(1, frame)], report.render()


def test_report_is_the_same_whatever_the_workers(tiny_dataset):
    X.set_image(tiny_dataset, X.TEST, S.IMAGE, 100, b"garbage")
    table = X.read(tiny_dataset, X.TRAIN)
    state = X.matrix(table, S.STATE, S.STATE_DIM)
    state[::7, 6] *= 1.5  # rot6d broken on many rows of several row groups
    X.write(tiny_dataset, X.TRAIN, X.set_matrix(table, S.STATE, state))
    one = validate(tiny_dataset, ValidateOptions(workers=1)).to_dict()
    two = validate(tiny_dataset, ValidateOptions(workers=2)).to_dict()
    assert two["checked"]["workers"] == 2
    for report in (one, two):
        report.pop("checked")
    assert one == two


def test_hub_snapshot_extras_are_tolerated(tiny_dataset):
    """What `snapshot_download(local_dir=...)` adds is not part of the dataset."""
    (tiny_dataset / ".gitattributes").write_text("*.parquet filter=lfs diff=lfs merge=lfs -text\n")
    cache = tiny_dataset / ".cache" / "huggingface" / "download" / "data"
    cache.mkdir(parents=True)
    (cache / "train-00000-of-00001.parquet.metadata").write_text("abc\n")
    assert validate(tiny_dataset, ValidateOptions(quick=True, workers=1)).ok


@pytest.mark.parametrize(
    "change, says",
    [
        (lambda info: info.update(counts=None), "counts must be a JSON object, not null"),
        (lambda info: info.pop("features"), "lacks features"),
        (lambda info: info.update(fps="abc"), 'fps must be a whole number, not "abc"'),
    ],
)
def test_a_damaged_info_record_is_a_finding_not_a_crash(tiny_dataset, change, says):
    """validate names what other commands refuse (they send the user to validate), and info is one line."""
    X.edit_json(tiny_dataset, S.INFO_PATH, change)
    report = validate(tiny_dataset, ValidateOptions(quick=True, workers=1))
    found = [f for f in report.findings(C.UNREADABLE) if f.file == S.INFO_PATH]
    assert len(found) == 1 and says in found[0].message, found
    res = runner.invoke(app, ["info", str(tiny_dataset)])
    assert res.exit_code != 0 and "Traceback" not in res.output and says in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1


def test_not_a_dataset_reports_missing_meta(tmp_path):
    (tmp_path / "data").mkdir()
    report = validate(tmp_path, ValidateOptions(workers=1))
    assert C.MISSING in report.failed()
    assert any(f.file == S.INFO_PATH for f in report.findings(C.MISSING))


def test_missing_folder_raises(tmp_path):
    with pytest.raises(FileNotFoundError, match="no dataset folder at"):
        validate(tmp_path / "nope")


def test_an_interrupted_reshard_is_named_as_such(tiny_dataset):
    """A re-shard killed midway leaves shards meta/info.json does not list and lacks some it does:
    validate says to run shard again, not to delete the only copy of the data."""
    import shutil

    listed = sorted((tiny_dataset / S.DATA_DIR).glob("train-*.parquet"))[0]
    shutil.move(listed, tiny_dataset / S.DATA_DIR / "train-00000-of-00009.parquet")
    report = validate(tiny_dataset, ValidateOptions(quick=True, workers=1))
    hints = [f.message for check in (C.EXTRA, C.MISSING) for f in report.findings(check)]
    assert any("an interrupted re-shard leaves these" in h for h in hints), hints
    assert any("an interrupted re-shard? run `orbitdata shard` again" in h for h in hints), hints
