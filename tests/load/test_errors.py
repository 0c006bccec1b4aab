"""Bad input gives a clear error that names the value, the place and the fix; nothing hangs in workers."""

from __future__ import annotations

import json
import traceback

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from datasets import load_dataset
from torch.utils.data import DataLoader

from orbitdata import schema as S
from orbitdata.load import WindowDataset, collate_windows, load_windows


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("hf-cache"))


def rewrite(path, change) -> None:
    """Apply ``change`` to a Parquet file's table, keeping its schema metadata."""
    table = pq.read_table(path)
    pq.write_table(change(table).cast(table.schema), path)


def test_missing_column(tiny_dataset_master, cache):
    for streaming in (False, True):
        with pytest.raises(ValueError, match=r"\['observation.segmentation'\] not in the dataset; available"):
            load_windows(
                tiny_dataset_master, columns=[S.IMAGE, "observation.segmentation"], streaming=streaming, cache_dir=cache
            )


def test_unknown_schema_version(tiny_dataset, cache):
    info_path = tiny_dataset / S.INFO_PATH
    info = json.loads(info_path.read_text())
    info["schema_version"] = "2.0"
    info_path.write_text(json.dumps(info))
    with pytest.raises(ValueError, match=r"schema version '2.0', but orbitdata .* reads schema 1.x"):
        load_windows(tiny_dataset, cache_dir=cache)
    del info["schema_version"]
    info_path.write_text(json.dumps(info))
    with pytest.raises(ValueError, match="has no schema_version"):
        load_windows(tiny_dataset, cache_dir=cache)
    info_path.unlink()
    with pytest.raises(FileNotFoundError, match=r"meta/info.json is missing"):
        load_windows(tiny_dataset, cache_dir=cache)


def test_missing_folder(tmp_path, cache):
    with pytest.raises(FileNotFoundError, match="no dataset folder at"):
        load_windows(tmp_path / "nope", cache_dir=cache)
    with pytest.raises(FileNotFoundError, match="no dataset folder at"):
        load_windows("./not/a/dataset", cache_dir=cache)


def test_window_longer_than_every_episode(tiny_dataset_master, cache):
    for streaming in (False, True):
        with pytest.raises(ValueError, match=r"longer than every selected episode .*longest: \d+ frames.*pad=True"):
            load_windows(tiny_dataset_master, context=8, horizon=400, streaming=streaming, cache_dir=cache)
    with pytest.raises(ValueError, match=r"a window of 400 real frames .*horizon padded.*use a shorter context"):
        load_windows(tiny_dataset_master, context=400, horizon=10, pad=True, cache_dir=cache)
    # Padding lets the horizon run past the end: the same long horizon now works.
    assert len(load_windows(tiny_dataset_master, context=8, horizon=400, pad=True, columns=[S.ACTION], cache_dir=cache))


def test_streaming_options_on_a_map_style_dataset(tiny_dataset_master, cache):
    with pytest.raises(ValueError, match="shuffle_buffer/seed are for streaming=True"):
        load_windows(tiny_dataset_master, shuffle_buffer=4, cache_dir=cache)


def test_a_steps_table_with_an_index_mapping_is_refused(tiny_dataset_master, cache):
    steps = load_dataset(str(tiny_dataset_master), split="train", cache_dir=cache)
    with pytest.raises(ValueError, match="select episodes with episodes=... instead"):
        WindowDataset(steps.select([5, 1, 2]))


def test_inconsistent_episodes_table(tiny_dataset, cache):
    path = next((tiny_dataset / S.EPISODES_DIR).glob("train-*.parquet"))
    rewrite(
        path,
        lambda t: t.set_column(
            t.schema.get_field_index(S.LENGTH), S.LENGTH, pc.add(t.column(S.LENGTH), pa.scalar(1, pa.int32()))
        ),
    )
    with pytest.raises(ValueError, match=r"episode \d+: the episodes table says \d+ frames but split 'train'"):
        load_windows(tiny_dataset, cache_dir=cache)


def test_out_of_order_frames_name_the_episode(tiny_dataset, cache):
    path = next((tiny_dataset / S.DATA_DIR).glob("train-*.parquet"))
    rewrite(path, lambda t: t.take(pa.array([1, 0, *range(2, t.num_rows)])))
    with pytest.raises(ValueError, match=r"episode \d+ in split 'train' .*: row 0 has frame_index 1, expected 0"):
        load_windows(tiny_dataset, cache_dir=cache)


def test_a_corrupt_image_names_episode_frame_and_column_even_in_workers(tiny_dataset, cache):
    path = next((tiny_dataset / S.DATA_DIR).glob("train-*.parquet"))

    def corrupt(table: pa.Table) -> pa.Table:
        images = table.column(S.IMAGE).to_pylist()
        images = [{"bytes": b"not a jpeg", "path": None}] * len(images)
        return table.set_column(table.schema.get_field_index(S.IMAGE), S.IMAGE, pa.array(images, S.IMAGE_STRUCT))

    rewrite(path, corrupt)
    ds = load_windows(tiny_dataset, columns=[S.IMAGE], cache_dir=cache)
    with pytest.raises(ValueError, match=r"episode \d+, window starting at frame 0, column 'observation.image'"):
        ds[0]
    batches = iter(DataLoader(ds, batch_size=4, num_workers=2, collate_fn=collate_windows, timeout=60))
    with pytest.raises(ValueError, match="not a decodable image") as err:
        next(batches)
    # torch's re-raise leaves the iterator in a reference cycle; collected by the GC, its
    # workers take 5 s each to be joined. Freed by reference count, they stop at once.
    traceback.clear_frames(err.value.__traceback__)
    del batches


def test_a_repo_id_with_its_revision_and_an_unknown_episodes_column(tiny_dataset_master, cache):
    from orbitdata.load.episodes import read_episodes

    with pytest.raises(FileNotFoundError, match=r"revision='v1' \(load_windows\('owner/name', revision='v1'\)\)"):
        load_windows("owner/name@v1", context=2, horizon=1, cache_dir=cache)
    with pytest.raises(ValueError, match=r"columns \['nope'\] are not in the episodes table"):
        read_episodes(tiny_dataset_master, ["nope"])
    assert read_episodes(tiny_dataset_master, [S.EPISODE_INDEX]).column_names == [S.EPISODE_INDEX]
