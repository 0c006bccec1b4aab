"""`orbitdata validate` on the dynamic tier: a generated dataset passes the tier's physics checks
(thrust to acceleration through the recorded fault and body, debris poses on their recorded motion,
the CW terms as flagged), and a copy with a corrupted fault record, a debris pose that jumps or a
flipped CW flag is refused with one line that names the episode and what is wrong."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitdata.cli.app import app
from orbitdata.info import sha256_file
from orbitdata.scenario.config import DYNAMIC
from orbitdata.validate import ValidateOptions, validate
from orbitdata.validate import checks as C

runner = CliRunner()


@pytest.fixture
def dynamic_copy(dynamic_master, tmp_path) -> Path:
    dst = tmp_path / "orbit"
    shutil.copytree(dynamic_master, dst)
    return dst


# ---- corrupting a copy the way a careless tool would: rewrite a shard, reseal meta/info.json --------
def _reseal(root: Path, rel: str) -> None:
    info_path = root / S.INFO_PATH
    info = json.loads(info_path.read_text())
    info["files"][rel] = {"sha256": sha256_file(root / rel), "bytes": (root / rel).stat().st_size}
    info_path.write_text(json.dumps(info, indent=2, sort_keys=True) + "\n")


def _rewrite(root: Path, rel: str, table: pa.Table) -> None:
    kind = rel.split("/")[0]
    schema = S.step_schema(DYNAMIC) if kind == S.DATA_DIR else S.episode_schema(DYNAMIC)
    rows_per_group = pq.ParquetFile(root / rel).metadata.row_group(0).num_rows
    pq.write_table(
        table.cast(S.with_hf_metadata(schema, kind, DYNAMIC)),
        root / rel,
        compression="zstd",
        row_group_size=rows_per_group,
    )
    _reseal(root, rel)


def _episodes(root: Path) -> list[tuple[str, dict]]:
    return [(f"{S.EPISODES_DIR}/{p.name}", row) for p in sorted((root / S.EPISODES_DIR).glob("*.parquet"))
            for row in pq.read_table(p).to_pylist()]  # fmt: skip


def _edit_episode(root: Path, index: int, edit) -> None:
    for rel in sorted({rel for rel, _ in _episodes(root)}):
        rows = pq.read_table(root / rel).to_pylist()
        for row in rows:
            if row[S.EPISODE_INDEX] == index:
                edit(row)
                _rewrite(root, rel, pa.Table.from_pylist(rows))
                return
    raise KeyError(index)


def _actions(root: Path, row: dict) -> np.ndarray:
    table = pq.read_table(root / row[S.DATA_FILE], columns=[S.ACTION]).slice(row[S.ROW_START], row[S.LENGTH])
    return np.asarray(table.column(S.ACTION).to_pylist())


def _refused_with_one_line(root: Path, check: str, episode: int) -> str:
    """Validate through the CLI: exit 1, one problem, in ``check``, on ``episode``. Returns its line."""
    result = runner.invoke(app, ["validate", str(root), "--workers", "1"])
    assert result.exit_code == 1, result.output
    lines = result.output.splitlines()
    assert lines[-1] == f"INVALID: 1 problem(s) in 1 check(s): {check}", result.output
    at = next(i for i, line in enumerate(lines) if line.lstrip().startswith(f"FAIL  {check}"))
    finding = lines[at + 1].strip()
    assert f" episode {episode} " in f" {finding}", finding
    assert not lines[at + 2].startswith(" " * 10), "one line per corruption"
    return finding


# ---- the clean dataset ----------------------------------------------------------------------------
def test_a_dynamic_dataset_passes_every_check_of_its_tier(dynamic_master, tmp_path):
    out = tmp_path / "report.json"
    result = runner.invoke(app, ["validate", str(dynamic_master), "--workers", "1", "--json", str(out)])
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    assert [c["name"] for c in report["checks"]] == [c.name for c in C.CHECKS + C.DYNAMIC_CHECKS]
    assert all(c["status"] == "pass" for c in report["checks"]), result.output
    quick = validate(dynamic_master, ValidateOptions(quick=True, workers=1))
    assert quick.ok and quick.status(C.DYN_RECORD) == "pass" and quick.status(C.DYN_THRUST) == "skip"


# ---- three corrupted copies, one line each ----------------------------------------------------------
def _faulty_episode(root: Path) -> tuple[dict, int, int]:
    """An episode whose fault shows, another thruster commanded after the onset (moving the fault
    onto it changes what the record predicts), and the first frame at which the fault shows."""
    for _, row in _episodes(root):
        fault = row[S.FAULT]
        if fault["kind"] == "none":
            continue
        onset, k = fault["onset_step"], fault["thruster"]
        actions = _actions(root, row)[:-1]  # the last frame's action is never flown
        shows = [t for t in range(onset, len(actions)) if fault["kind"] == "stuck" or actions[t, k] > 0.05]
        busy = [j for j in range(S.ACTION_DIM) if shows and actions[shows[0] :, j].max() > 0.05 and j != k]
        if busy:
            return row, busy[0], shows[0]
    pytest.fail("no episode of the tiny dataset has a fault that shows")


def test_a_corrupted_fault_record_is_named(dynamic_copy):
    row, other, _ = _faulty_episode(dynamic_copy)
    index, recorded = row[S.EPISODE_INDEX], row[S.FAULT]["thruster"]
    _edit_episode(dynamic_copy, index, lambda r: r[S.FAULT].__setitem__("thruster", other))
    line = _refused_with_one_line(dynamic_copy, C.DYN_THRUST, index)
    assert f"the record has thruster {other} {row[S.FAULT]['kind']}" in line
    assert f"shows thruster {recorded} " in line and line.endswith("the fault record is wrong")


def test_a_fault_onset_moved_is_named(dynamic_copy):
    row, _, shows = _faulty_episode(dynamic_copy)
    index, moved = row[S.EPISODE_INDEX], shows + 1  # the record now says healthy where the fault shows
    _edit_episode(dynamic_copy, index, lambda r: r[S.FAULT].__setitem__("onset_step", moved))
    line = _refused_with_one_line(dynamic_copy, C.DYN_THRUST, index)
    assert "the motion shows the recorded fault from frame" in line
    assert f"from frame {moved}: the fault record is wrong" in line


def test_a_debris_pose_that_jumps_is_named(dynamic_copy):
    _, row = next((rel, r) for rel, r in _episodes(dynamic_copy) if r[S.N_OBSTACLES] and r[S.LENGTH] > 8)
    rel, index = row[S.DATA_FILE], row[S.EPISODE_INDEX]
    table = pq.read_table(dynamic_copy / rel)
    poses = table.column(S.OBSTACLE_POSES).to_pylist()
    poses[row[S.ROW_START] + 5][0][1] += 0.3  # obstacle 0, frame 5: 30 cm along y
    column = pa.array(poses, type=table.schema.field(S.OBSTACLE_POSES).type)
    _rewrite(dynamic_copy, rel, table.set_column(table.column_names.index(S.OBSTACLE_POSES), S.OBSTACLE_POSES, column))
    line = _refused_with_one_line(dynamic_copy, C.DYN_DEBRIS, index)
    assert "frame 5: obstacle 0's pose jumps at frame 5: 0.3 m" in line


def test_a_flipped_cw_flag_is_named_once_for_the_cubesat_and_the_debris(dynamic_copy):
    _, row = max(((rel, r) for rel, r in _episodes(dynamic_copy) if r[S.CW]), key=lambda x: x[1][S.LENGTH])
    index = row[S.EPISODE_INDEX]
    _edit_episode(dynamic_copy, index, lambda r: r.__setitem__(S.CW, False))
    line = _refused_with_one_line(dynamic_copy, C.DYN_CW, index)
    assert "cw is false in the episodes table, but the motion of the CubeSat" in line
    assert line.endswith("(it fits cw true): the cw flag is wrong")
    # the driver's seams and the workers' row groups find the same (rows of 64: episodes span groups)
    report = validate(dynamic_copy, ValidateOptions(workers=2))
    assert report.failed() == [C.DYN_CW] and report.findings(C.DYN_CW)[0].episode == index


def test_a_malformed_record_is_reported_in_quick_mode(dynamic_copy):
    _, row = next(x for x in _episodes(dynamic_copy) if x[1][S.FAULT]["kind"] != "none")
    index = row[S.EPISODE_INDEX]
    _edit_episode(dynamic_copy, index, lambda r: r[S.FAULT].__setitem__("thruster", 9))
    report = validate(dynamic_copy, ValidateOptions(quick=True, workers=1))
    assert report.failed() == [C.DYN_RECORD]
    finding = report.findings(C.DYN_RECORD)[0]
    assert finding.episode == index and "fault thruster must be in 0..7, got 9" in finding.message


# ---- the static checks that the tier changes ---------------------------------------------------------
def _edit_rows(root: Path, column: str, edit) -> tuple[int, int]:
    """Apply ``edit(values (list), row)`` to frame 6 of the first long episode; returns (episode, frame)."""
    _, row = next(x for x in _episodes(root) if x[1][S.LENGTH] > 12)
    rel, at = row[S.DATA_FILE], row[S.ROW_START] + 6
    table = pq.read_table(root / rel)
    values = table.column(column).to_pylist()
    edit(values, at)
    column_array = pa.array(values, type=table.schema.field(column).type)
    _rewrite(root, rel, table.set_column(table.column_names.index(column), column, column_array))
    return row[S.EPISODE_INDEX], 6


def test_the_tiers_kinematics_catch_a_position_jump(dynamic_copy):
    """The tier's body (centre of mass offset, anisotropic inertia) flies the kinematic check: a
    clean dataset passes it (above) and a 2 cm jump in p fails it, on the steps into and out of it."""
    episode, frame = _edit_rows(dynamic_copy, S.STATE, lambda v, i: v[i].__setitem__(1, v[i][1] + 0.02))
    report = validate(dynamic_copy, ValidateOptions(workers=1))
    assert report.failed() == [C.KIN_POSITION]
    assert {(f.episode, f.frame) for f in report.findings(C.KIN_POSITION)} == {(episode, frame), (episode, frame + 1)}


def test_depth_low_is_checked_around_the_dropped_depth_pixels(dynamic_copy):
    """Dropped depth pixels may hide anything in [near, far] from depth_low's pooling, but a cell
    with no empty pixel is exact and no cell may leave what its pixels allow: 1 m more is caught."""
    episode, frame = _edit_rows(dynamic_copy, S.DEPTH_LOW, lambda v, i: v.__setitem__(i, [x + 1.0 for x in v[i]]))
    report = validate(dynamic_copy, ValidateOptions(workers=1))
    assert C.DEPTH_LOW in report.failed() and set(report.failed()) <= {C.DEPTH_LOW, C.STATS}  # stats: a train row
    assert [(f.episode, f.frame) for f in report.findings(C.DEPTH_LOW)] == [(episode, frame)]


def test_validating_the_tier_loads_neither_mujoco_nor_ompl(dynamic_master):
    from test_imports import run

    assert run("cli", ["validate", str(dynamic_master), "--workers", "1"]) == {"code": 0, "heavy": []}
