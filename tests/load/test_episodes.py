"""Reading one episode: its own rows, only its rows, and clear errors for bad indices."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from orbitdata import schema as S
from orbitdata.load.episodes import EpisodeNotFound, load_episode, read_episodes
from orbitdata.load.rows import read_cells, read_rows


def _all_steps(root):
    files = sorted((root / S.DATA_DIR).glob("*.parquet"))
    return pa.concat_tables(
        [pq.read_table(f, columns=[S.EPISODE_INDEX, S.FRAME_INDEX, S.STATE, S.ACTION]) for f in files]
    )


def test_each_episode_reads_exactly_its_rows(tiny_dataset_master):
    steps = _all_steps(tiny_dataset_master)
    ep_col = steps.column(S.EPISODE_INDEX).to_numpy()
    states = np.stack(steps.column(S.STATE).to_numpy(zero_copy_only=False))
    episodes = read_episodes(tiny_dataset_master)
    assert episodes.column(S.EPISODE_INDEX).to_pylist() == sorted(set(ep_col.tolist()))
    for index, length in zip(episodes.column(S.EPISODE_INDEX).to_pylist(), episodes.column(S.LENGTH).to_pylist()):
        ep = load_episode(tiny_dataset_master, index)
        assert len(ep) == length == (ep_col == index).sum()
        np.testing.assert_array_equal(ep.states, states[ep_col == index])
        np.testing.assert_array_equal(ep.positions, states[ep_col == index][:, 0:3])
        assert ep.actions.shape == (length, S.ACTION_DIM)
        assert ep.positions[0] == pytest.approx([0, 0, 0], abs=1e-6)  # p_0 = 0 by contract
        (first, last) = ep.rgb([0, length - 1])
        assert first.shape == last.shape == (64, 64, 3) and first.dtype == np.uint8
        (depth,) = ep.depth([length - 1])
        assert depth.shape == (64, 64) and depth.dtype == np.float32
        assert (ep.collision_at is not None) == (ep.meta[S.OUTCOME] == "collision")


def test_camera_axis_is_a_unit_vector(tiny_dataset_master):
    ep = load_episode(tiny_dataset_master, 0)
    np.testing.assert_allclose(np.linalg.norm(ep.camera_axis, axis=1), 1.0, atol=1e-4)


@pytest.mark.parametrize("bad", [99, -1])
def test_a_missing_episode_names_the_range(tiny_dataset_master, bad):
    with pytest.raises(EpisodeNotFound, match=r"episode .* is not in .*6 episodes, indices 0 to 5"):
        load_episode(tiny_dataset_master, bad)


def test_a_folder_that_is_not_a_dataset(tmp_path):
    with pytest.raises(FileNotFoundError, match="not a finished orbitdata dataset"):
        load_episode(tmp_path, 0)
    with pytest.raises(FileNotFoundError, match="no dataset folder at"):
        load_episode(tmp_path / "nope", 0)


def test_rows_that_do_not_match_the_episode_are_reported(tiny_dataset):
    path = sorted((tiny_dataset / S.EPISODES_DIR).glob("train-*.parquet"))[0]
    table = pq.read_table(path)
    shifted = pa.compute.add(table.column(S.ROW_START), 1)
    table = table.set_column(table.schema.get_field_index(S.ROW_START), S.ROW_START, shifted)
    pq.write_table(table, path)
    index = table.column(S.EPISODE_INDEX)[0].as_py()
    with pytest.raises(ValueError, match="orbitdata validate"):
        load_episode(tiny_dataset, index)


def test_row_reads_agree_across_row_groups(tiny_dataset_master):
    path = sorted((tiny_dataset_master / S.DATA_DIR).glob("*.parquet"))[0]
    assert pq.ParquetFile(path).metadata.num_row_groups > 1  # the tiny config uses 64-row groups
    whole = pq.read_table(path, columns=[S.FRAME_INDEX]).column(S.FRAME_INDEX).to_pylist()
    assert read_rows(path, 60, 70, [S.FRAME_INDEX]).column(S.FRAME_INDEX).to_pylist() == whole[60:70]
    assert read_cells(path, [70, 3, 64, 63], S.FRAME_INDEX) == [whole[70], whole[3], whole[64], whole[63]]
    with pytest.raises(ValueError, match="out of range"):
        read_rows(path, 0, len(whole) + 1, [S.FRAME_INDEX])
