"""Where windows come from: a local dataset folder or a Hub repo id, read through ``load_dataset``.

Before anything is read, the schema version in ``meta/info.json`` is checked: a local folder
must have one; a Hub repo is checked when the file can be fetched (online, or in the Hub cache).
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa

from orbitdata import __version__, schema as S

EPISODES_CONFIG = "episodes"  # the card's config name for the episodes table
SUPPORTED_MAJOR = S.SCHEMA_VERSION.split(".")[0]  # minor versions only add, so they stay readable


def local_folder(source: str | Path) -> Path | None:
    """The dataset folder if ``source`` names one, None for a Hub repo id; raises for a missing path."""
    path = Path(source).expanduser()
    if path.exists():
        if not path.is_dir():
            raise NotADirectoryError(f"{source} is a file; give the dataset folder (the one with data/ and meta/)")
        return path
    text = str(source)
    if isinstance(source, Path) or text.startswith((".", "/", "~")) or text.count("/") != 1:
        raise FileNotFoundError(f"no dataset folder at {source}; give a local folder or a Hub repo id like 'user/name'")
    return None


def read_info(source: str | Path, load_kwargs: dict) -> dict | None:
    """``meta/info.json`` of the source; None when a Hub repo's file cannot be fetched."""
    folder = local_folder(source)
    if folder is not None:
        path = folder / S.INFO_PATH
        if not path.is_file():
            raise FileNotFoundError(
                f"{path} is missing: {folder} is not a complete orbitdata dataset "
                "(finish it with `orbitdata generate`, or check it with `orbitdata validate`)"
            )
        try:
            return json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(f"{path} is not valid JSON ({err}); run `orbitdata validate`") from None
    try:
        from huggingface_hub import hf_hub_download

        path = hf_hub_download(
            repo_id=str(source), filename=S.INFO_PATH, repo_type="dataset",
            revision=load_kwargs.get("revision"), token=load_kwargs.get("token"),
        )
        return json.loads(Path(path).read_text())
    except Exception:  # offline, private, or not an orbitdata repo: load_dataset will say more
        return None


def check_schema_version(info: dict | None, source: str | Path) -> None:
    """Raise unless the dataset's schema major version is the one this code reads."""
    if info is None:
        return
    version = info.get("schema_version")
    if version is None:
        raise ValueError(f"{source}: {S.INFO_PATH} has no schema_version; it was not written by orbitdata")
    if str(version).split(".")[0] != SUPPORTED_MAJOR:
        raise ValueError(
            f"{source} has schema version {version!r}, but orbitdata {__version__} reads schema "
            f"{SUPPORTED_MAJOR}.x; install the orbitdata release that matches the dataset"
        )


def load_steps(source: str | Path, split: str, streaming: bool, load_kwargs: dict, columns=None):
    """The steps table of one split: a memory-mapped ``Dataset``, or an ``IterableDataset`` in Arrow format."""
    from datasets import load_dataset

    kwargs = dict(load_kwargs)
    if local_folder(source) is not None and "data_files" not in kwargs and "data_dir" not in kwargs:
        # Named explicitly, the files' mtimes enter the cache key; through the card's configs
        # they do not, and a rewritten dataset would be read from a stale Arrow cache.
        kwargs["data_files"] = {split: f"{S.DATA_DIR}/{split}-*.parquet"}
    if streaming and columns is not None:
        kwargs["columns"] = list(columns)  # Parquet reads only these columns
    steps = load_dataset(str(source), split=split, streaming=streaming, **kwargs)
    return steps.with_format("arrow") if streaming else steps


def load_episode_table(source: str | Path, split: str, load_kwargs: dict) -> pa.Table:
    """The episodes config of one split as an Arrow table (small: one row per episode)."""
    from datasets import load_dataset

    kwargs = {k: v for k, v in load_kwargs.items() if k not in ("columns", "streaming", "name")}
    episodes = load_dataset(str(source), EPISODES_CONFIG, split=split, streaming=True, **kwargs)
    batches = list(episodes.with_format("arrow").iter(batch_size=100_000))
    if not batches:
        raise ValueError(f"{source}: split {split!r} has no episodes")
    return pa.concat_tables(batches)
