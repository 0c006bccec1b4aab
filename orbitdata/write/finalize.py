"""Finalize a dataset: shards from the parts (or re-shard), then stats, meta/info.json and the card.

``orbitdata shard`` is this step on its own. The optional figure (``meta/overview.png``) is
drawn by a callback, so the writer does not depend on the plotting code: the CLI passes
:func:`orbitdata.viz.overview_figure`.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Callable

import pyarrow as pa

from orbitdata import schema as S
from orbitdata.config import GenerationConfig
from orbitdata.info import Info
from orbitdata.load.source import read_info
from orbitdata.write import parts
from orbitdata.write.card import render_card
from orbitdata.write.meta import build_info, card_repo, write_json
from orbitdata.write.parts import atomic_write
from orbitdata.write.plan import plan_units
from orbitdata.write.shard import write_shards


class NoDataset(FileNotFoundError):
    """The folder holds neither the part files of a generation nor a finished dataset."""


# Draws a figure of the dataset in OUT from its episodes table and config; returns the path it
# wrote (relative to OUT), or None when it cannot draw (e.g. without the plotting extra).
Figure = Callable[[Path, pa.Table, GenerationConfig], "str | None"]


def existing_config(out: Path) -> dict | None:
    """The config of the generation in ``out``: its parts' manifest, else its meta/info.json."""
    manifest = parts.read_manifest(out)
    if manifest is not None:
        return manifest["config"]
    if (out / S.INFO_PATH).exists():
        return read_info(out).config
    return None


def finalize(
    out: Path,
    config: GenerationConfig | None = None,
    repo_id: str | None = None,
    max_shard_bytes: int | None = None,
    figure: Figure | None = None,
) -> Info:
    """Compact parts (or re-shard existing shards) and write meta/ and the card. Returns the info."""
    out = Path(out)
    if config is None:
        existing = existing_config(out)
        if existing is None:
            raise NoDataset(
                f"{out} holds no orbitdata dataset (no {S.PARTS_DIR}/{parts.MANIFEST_FILE} or "
                f"{S.INFO_PATH}); pass a folder made by `orbitdata generate`"
            )
        config = GenerationConfig.from_dict(existing, where=f"{out} config")
        if (out / S.INFO_PATH).exists() and parts.parts_dir(out).exists():
            # info.json is written last, before the parts are removed: these were left by a kill while a
            # finished generation removed them (or a later rerun of it), and its shards hold every episode
            shutil.rmtree(parts.parts_dir(out))
        if parts.read_manifest(out) is not None and not (out / S.INFO_PATH).exists():  # parts to compact: only
            # a finished generation's (with info.json, written last, a finished one died removing its parts)
            units = plan_units(config.dataset)
            done = [u for u in units if parts.is_done(out, u.name)]
            if len(done) < len(units):
                raise NoDataset(
                    f"{out} holds an unfinished generation ({sum(len(u.episodes) for u in done)} of "
                    f"{config.dataset.episodes} episodes): run the same `orbitdata generate` command again to finish it"
                )
    if max_shard_bytes is not None:
        config = config.replace(dataset={"max_shard_bytes": int(max_shard_bytes)})
    result = write_shards(out, config.dataset, config.tier)
    write_json(out, S.STATS_PATH, result.stats)
    sizes = {S.DATA_DIR: {}, S.EPISODES_DIR: {}}
    for rel in result.files:
        folder, name = rel.split("/")
        split = name.split("-")[0]
        sizes[folder][split] = sizes[folder].get(split, 0) + (out / rel).stat().st_size
    files = result.files + [S.STATS_PATH]
    overview = figure(out, result.episodes, config) if figure is not None else None
    if overview:
        files.append(overview)
    info = build_info(config, result.episodes, out, files)
    repo = repo_id or card_repo(out) or Path(os.path.abspath(out)).name  # "." names its folder
    card = render_card(info, config, sizes, repo=repo, overview=overview, episodes=result.episodes)
    atomic_write(out / S.CARD_PATH, card.encode())
    info = build_info(config, result.episodes, out, files + [S.CARD_PATH])
    write_json(out, S.INFO_PATH, info.to_dict())  # last: its presence means the layout is complete
    if parts.parts_dir(out).exists():
        shutil.rmtree(parts.parts_dir(out))
    return info
