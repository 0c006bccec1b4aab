"""``orbitmodel eval rollout``: the Stage I evaluation end to end, and the depth head by distance band."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from orbitmodel.cli.app import app
from orbitmodel.plan.depth_bands import depth_by_band

runner = CliRunner()


def test_depth_by_band_counts_misses_and_phantoms_where_the_planner_looks():
    true = torch.tensor([1.0, 1.5, 3.0, 7.0, 12.0, 40.0])
    pred = torch.tensor([1.5, 15.0, 3.0, 9.0, 8.0, 40.0])  # the 1.5 m cell is missed, the 12 m one a phantom
    out = depth_by_band(pred, true, edges=(2.0, 5.0, 10.0), seen_within=10.0)
    near, mid, far, beyond = out["bands"]
    assert (near["from_m"], near["to_m"], near["cells"]) == (0.0, 2.0, 2)
    assert near["mae_m"] == pytest.approx((0.5 + 13.5) / 2) and near["missed"] == pytest.approx(0.5)
    assert (mid["cells"], mid["mae_m"], mid["missed"]) == (1, 0.0, 0.0)
    assert (far["cells"], far["mae_m"]) == (1, pytest.approx(2.0))
    assert beyond["to_m"] is None and beyond["cells"] == 2 and beyond["missed"] == pytest.approx(0.5)
    assert out["phantom"] == pytest.approx(0.5)  # 12 m predicted at 8 m; 40 m predicted at 40 m
    empty = depth_by_band(torch.tensor([1.0]), torch.tensor([1.0]))
    assert empty["bands"][1]["cells"] == 0 and empty["bands"][1]["mae_m"] is None and empty["phantom"] is None


def test_eval_rollout_writes_the_curves_the_depth_bands_and_the_figures(tiny_run, tiny_dataset_master, tmp_path):
    out = tmp_path / "eval"
    res = runner.invoke(
        app,
        [
            "eval",
            "rollout",
            str(tiny_run),
            str(tiny_dataset_master),
            "--windows",
            "2",
            "--horizon",
            "5",
            "--out",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "depth by true distance" in res.output and "effective rank" in res.output
    result = json.loads((out / "rollout.json").read_text())
    assert len(result["nmse"]) == len(result["persistence_nmse"]) == 5
    bands = result["depth_by_band"]
    assert bands["range_m"] == 10.0
    frames = 2 * (8 + 5)  # every frame of both windows, 16 x 16 cells each
    assert sum(b["cells"] for b in bands["bands"]) == frames * 256
    assert (out / "rollout.png").stat().st_size > 0 and (out / "depth.png").stat().st_size > 0


@pytest.mark.parametrize("n", [2, 3, 5, 100])
def test_the_shuffled_baseline_never_gives_a_window_its_own_actions(n):
    from orbitmodel.evaluate.rollout import derangement

    for seed in range(4):
        d = derangement(n, seed)
        assert sorted(d.tolist()) == list(range(n)) and not np.any(d == np.arange(n))
        assert np.array_equal(d, derangement(n, seed))  # same seed, same pairing


def test_a_horizon_longer_than_every_episode_names_the_largest_that_fits(tiny_run, tiny_dataset_master, tmp_path):
    args = ["eval", "rollout", str(tiny_run), str(tiny_dataset_master), "--windows", "2", "--out", str(tmp_path)]
    res = runner.invoke(app, [*args, "--horizon", "200"])
    assert res.exit_code == 2, res.output
    line = res.output.strip().splitlines()[-1]
    assert line.startswith("error: --horizon 200: 8 context and 200 horizon steps") and "pad=True" not in line
    from orbitdata import schema as S
    from orbitdata.load.tables import load_episode_table
    from orbitmodel.model.world_model import WorldModel

    longest = max(load_episode_table(str(tiny_dataset_master), "test", {}).column(S.LENGTH).to_pylist())
    step = WorldModel.from_pretrained(tiny_run).config.frame_step
    largest = longest // step - 8
    assert f"(longest: {longest} frames); give --horizon {largest} or less" in line, line
    from orbitdata.load.index import NoWindow
    from orbitmodel.data import load_model_windows

    assert len(load_model_windows(str(tiny_dataset_master), step, split="test", context=8, horizon=largest)) >= 1
    with pytest.raises(NoWindow):
        load_model_windows(str(tiny_dataset_master), step, split="test", context=8, horizon=largest + 1)
