"""meta/overview.png: written by shard, embedded in the card, deterministic, fast, optional."""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import pyarrow as pa
import pytest
from PIL import Image

from orbitdata import schema as S
from orbitdata.load.episodes import read_episodes
from orbitdata.viz.overview import frames_to_show, sample_episodes, write_overview


def test_generate_writes_the_overview_and_the_card_embeds_it(tiny_dataset_master):
    path = tiny_dataset_master / S.OVERVIEW_PATH
    with Image.open(path) as im:
        assert im.format == "PNG" and im.size[0] >= 1400 and im.size[1] >= 600
    info = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())
    assert S.OVERVIEW_PATH in info["files"]
    assert f"]({S.OVERVIEW_PATH})" in (tiny_dataset_master / S.CARD_PATH).read_text()


def test_the_overview_is_deterministic_and_fast(tiny_dataset):
    before = (tiny_dataset / S.OVERVIEW_PATH).read_bytes()
    (tiny_dataset / S.OVERVIEW_PATH).unlink()
    episodes = read_episodes(tiny_dataset)
    start = time.monotonic()
    write_overview(tiny_dataset, episodes.take(np.arange(episodes.num_rows)[::-1]))  # row order must not matter
    assert time.monotonic() - start < 10
    assert (tiny_dataset / S.OVERVIEW_PATH).read_bytes() == before


def test_samples_are_typical_episodes():
    table = pa.table({
        S.EPISODE_INDEX: [0, 1, 2, 3, 4],
        S.LEVEL: ["expert", "expert", "expert", "risky", "expert"],
        S.OUTCOME: ["success", "success", "success", "collision", "collision"],
        S.LENGTH: [100, 300, 150, 40, 90],
        S.DATA_FILE: ["data/train-00000-of-00001.parquet"] * 5,
        S.ROW_START: [0, 100, 400, 550, 590],
    })
    picks = sample_episodes(table)
    assert {k: v[S.EPISODE_INDEX] for k, v in picks.items()} == {
        ("expert", "success"): 2, ("risky", "collision"): 3, ("expert", "collision"): 4}


def test_frames_to_show_start_fill_and_end(tiny_dataset_master):
    pick = read_episodes(tiny_dataset_master).slice(0, 1).to_pylist()[0]
    frames = frames_to_show(tiny_dataset_master, pick)
    assert frames[0] == 0 and frames == sorted(set(frames))
    assert frames[-1] == round(0.9 * (pick[S.LENGTH] - 1))


def test_an_empty_table_is_refused(tiny_dataset):
    with pytest.raises(ValueError, match="no episodes"):
        write_overview(tiny_dataset, read_episodes(tiny_dataset).slice(0, 0))


def test_shard_skips_the_overview_without_matplotlib(tiny_dataset, monkeypatch):
    from orbitdata.write.generate import shard

    (tiny_dataset / S.OVERVIEW_PATH).unlink()
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.delitem(sys.modules, "orbitdata.viz.overview", raising=False)
    info = shard(tiny_dataset)
    assert not (tiny_dataset / S.OVERVIEW_PATH).exists()
    assert S.OVERVIEW_PATH not in info["files"]
    assert S.OVERVIEW_PATH not in (tiny_dataset / S.CARD_PATH).read_text()
