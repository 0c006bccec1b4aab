"""meta/overview.png: written by shard, embedded in the card, deterministic, fast, optional."""

from __future__ import annotations

import json
import sys

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from PIL import Image

from orbitdata import schema as S
from orbitdata.codecs import decode_depth
from orbitdata.load.episodes import read_episodes
from orbitdata.load.rows import RowReader, read_cells
from orbitdata.viz import overview_figure
from orbitdata.viz.overview import frames_to_show, sample_episodes, write_overview

FAR = 50.1  # m, the camera's far plane in the tiny config


def test_generate_writes_the_overview_and_the_card_embeds_it(tiny_dataset_master):
    path = tiny_dataset_master / S.OVERVIEW_PATH
    with Image.open(path) as im:
        assert im.format == "PNG" and im.size[0] >= 1400 and im.size[1] >= 600
    info = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())
    assert S.OVERVIEW_PATH in info["files"]
    assert f"]({S.OVERVIEW_PATH})" in (tiny_dataset_master / S.CARD_PATH).read_text()


def test_the_overview_is_deterministic_and_reads_only_what_it_shows(tiny_dataset, monkeypatch):
    before = (tiny_dataset / S.OVERVIEW_PATH).read_bytes()
    (tiny_dataset / S.OVERVIEW_PATH).unlink()
    episodes = read_episodes(tiny_dataset)
    reads = []
    read_row_group = pq.ParquetFile.read_row_group
    monkeypatch.setattr(
        pq.ParquetFile, "read_row_group", lambda self, g, *a, **k: reads.append(g) or read_row_group(self, g, *a, **k)
    )
    write_overview(tiny_dataset, episodes.take(np.arange(episodes.num_rows)[::-1]), FAR)  # row order must not matter
    read = len(reads)
    assert (tiny_dataset / S.OVERVIEW_PATH).read_bytes() == before
    # The work does not grow with the dataset: the row groups of the picked episodes' depth_low,
    # then, per data file, those that hold the frames shown.
    picks = sample_episodes(episodes)
    expected, frames_by_file = 0, {}
    for pick in picks.values():
        starts = RowReader(tiny_dataset / pick[S.DATA_FILE]).starts
        first, end = pick[S.ROW_START], pick[S.ROW_START] + pick[S.LENGTH]
        expected += int(((starts[:-1] < end) & (starts[1:] > first)).sum())
        groups = {
            int(np.searchsorted(starts, first + t, side="right")) - 1 for t in frames_to_show(tiny_dataset, pick, FAR)
        }
        frames_by_file.setdefault(pick[S.DATA_FILE], set()).update(groups)
    expected += sum(len(groups) for groups in frames_by_file.values())
    assert read == expected


def test_samples_are_typical_episodes():
    table = pa.table(
        {
            S.EPISODE_INDEX: [0, 1, 2, 3, 4],
            S.LEVEL: ["expert", "expert", "expert", "risky", "expert"],
            S.OUTCOME: ["success", "success", "success", "collision", "collision"],
            S.LENGTH: [100, 300, 150, 40, 90],
            S.DATA_FILE: ["data/train-00000-of-00001.parquet"] * 5,
            S.ROW_START: [0, 100, 400, 550, 590],
        }
    )
    picks = sample_episodes(table)
    assert {k: v[S.EPISODE_INDEX] for k, v in picks.items()} == {
        ("expert", "success"): 2,
        ("risky", "collision"): 3,
        ("expert", "collision"): 4,
    }


def test_frames_to_show_start_fill_and_end(tiny_dataset_master):
    moved = 0
    for pick in read_episodes(tiny_dataset_master).to_pylist():
        frames = frames_to_show(tiny_dataset_master, pick, FAR)
        length = pick[S.LENGTH]
        assert frames[0] == 0 and frames == sorted(set(frames)) and len(frames) == 3
        end = round(0.9 * (length - 1))
        assert frames[-1] == end
        # The middle frame is where obstacles fill the most of the view between a quarter of the
        # way and the end, measured here on the full-resolution depth (pixels with a return).
        start = max(1, min(length // 4, end - 1))
        depth = read_cells(
            tiny_dataset_master / pick[S.DATA_FILE], [pick[S.ROW_START] + t for t in range(start, end)], S.DEPTH
        )
        fill = np.array([(decode_depth(d["bytes"]) > 0).mean() for d in depth])
        middle = frames[1] - start
        assert fill[middle] >= fill.max() - 0.05, (pick[S.EPISODE_INDEX], fill[middle], fill.max())
        moved += middle > 0
    assert moved, "the fill frame never moved off the first candidate: the fill is not measured"


def test_an_empty_table_is_refused(tiny_dataset):
    with pytest.raises(ValueError, match="no episodes"):
        write_overview(tiny_dataset, read_episodes(tiny_dataset).slice(0, 0), FAR)


def test_finalize_skips_the_overview_without_matplotlib(tiny_dataset, monkeypatch):
    from orbitdata.write.finalize import finalize

    (tiny_dataset / S.OVERVIEW_PATH).unlink()
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.delitem(sys.modules, "orbitdata.viz.overview", raising=False)
    info = finalize(tiny_dataset, figure=overview_figure)
    assert not (tiny_dataset / S.OVERVIEW_PATH).exists()
    assert S.OVERVIEW_PATH not in info.files
    assert S.OVERVIEW_PATH not in (tiny_dataset / S.CARD_PATH).read_text()
