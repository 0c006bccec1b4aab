"""``generate``: plan, fly and write a dataset, resumably; then ``shard`` it into its final layout."""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from orbitdata import __version__, schema as S
from orbitdata.config import GenerationConfig
from orbitdata.dataset import parts
from orbitdata.dataset.card import render_card
from orbitdata.dataset.executors import run_local, run_ray
from orbitdata.dataset.meta import build_info, write_json
from orbitdata.dataset.parts import atomic_write
from orbitdata.dataset.plan import plan_units
from orbitdata.dataset.shard import StorageSettings, write_shards

OWNED = (S.DATA_DIR, S.EPISODES_DIR, S.META_DIR, S.PARTS_DIR, S.CARD_PATH)


class DatasetExists(RuntimeError):
    """OUT holds a dataset (or other files) that this run would clobber."""


@dataclass
class Progress:
    """What a progress callback receives after every finished unit."""

    units_done: int
    units_total: int
    episodes_done: int  # including units finished by an earlier, interrupted run
    episodes_new: int  # flown by this run (for rates)
    episodes_total: int
    frames_done: int
    elapsed: float


def _plan_record(config: GenerationConfig) -> dict:
    return {"config": config.to_dict(), "schema_version": S.SCHEMA_VERSION, "codebase_version": __version__}


def _existing_config(out: Path) -> dict | None:
    plan = parts.read_plan(out)
    if plan is not None:
        return plan["config"]
    info = out / S.INFO_PATH
    if info.exists():
        return json.loads(info.read_text()).get("config")
    return None


def prepare_output(out: Path, config: GenerationConfig, overwrite: bool) -> bool:
    """Make OUT ready. Returns True if the dataset there is already complete."""
    if out.exists() and not out.is_dir():
        raise DatasetExists(f"{out} exists and is not a folder; choose another OUT")
    existing = _existing_config(out) if out.exists() else None
    mine = json.loads(json.dumps(config.to_dict()))  # tuples -> lists, as stored
    if existing is not None and existing != mine:
        if not overwrite:
            raise DatasetExists(
                f"{out} holds a dataset generated with a different config; "
                "pass --overwrite to replace it, or choose another OUT"
            )
        clear_output(out)
    elif existing is None and out.exists() and any(out.iterdir()):
        if not overwrite:
            raise DatasetExists(f"{out} is not empty and holds no orbitdata dataset; choose an empty folder or pass --overwrite")
        clear_output(out)
    complete = (out / S.INFO_PATH).exists() and not parts.parts_dir(out).exists() and existing == mine
    if not complete:
        try:
            out.mkdir(parents=True, exist_ok=True)
            parts.write_plan(out, _plan_record(config))
        except OSError as exc:
            raise PermissionError(
                f"cannot write to {out} ({exc.strerror}); choose another OUT or fix its permissions"
            ) from None
    return complete


def clear_output(out: Path) -> None:
    """Remove what orbitdata writes in OUT (and nothing else)."""
    for name in OWNED:
        path = out / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()


def generate(
    out: Path,
    config: GenerationConfig,
    workers: int = 1,
    executor: str = "local",
    ray_address: str | None = None,
    overwrite: bool = False,
    progress: Callable[[Progress], None] | None = None,
    repo_id: str | None = None,
) -> dict:
    """Generate (or resume) the dataset in ``out`` and shard it. Returns ``meta/info.json``."""
    out = Path(out)
    if executor not in ("local", "ray"):
        raise ValueError(f"unknown executor {executor!r}; expected 'local' or 'ray'")
    if prepare_output(out, config, overwrite):
        return json.loads((out / S.INFO_PATH).read_text())
    parts.remove_temporaries(parts.parts_dir(out))
    units = plan_units(config.dataset)
    todo = [u for u in units if not parts.is_done(out, u.name)]
    total_eps = config.dataset.episodes
    done_eps = sum(len(u.episodes) for u in units if parts.is_done(out, u.name))
    frames, new_eps, start = 0, 0, time.monotonic()
    cfg = config.to_dict()
    results = run_local(cfg, todo, workers) if executor == "local" else run_ray(cfg, todo, ray_address, workers)
    by_index = {u.index: u for u in units}
    finished = len(units) - len(todo)
    for result in results:
        unit = by_index[result.unit]
        parts.write_unit(out, unit.name, result.steps, result.episodes)
        finished += 1
        done_eps += len(unit.episodes)
        new_eps += len(unit.episodes)
        frames += result.frames
        if progress:
            progress(Progress(finished, len(units), done_eps, new_eps, total_eps, frames, time.monotonic() - start))
    return shard(out, config, repo_id=repo_id)


def _write_overview(out: Path, episodes) -> str | None:
    """meta/overview.png for the card, when the plotting extra (orbitdata[viz]) is installed."""
    try:
        import matplotlib  # noqa: F401  (only the optional dependency may be missing)
    except ImportError:
        return None
    from orbitdata.viz.overview import write_overview

    write_overview(out, episodes)
    return S.OVERVIEW_PATH


def shard(out: Path, config: GenerationConfig | None = None, repo_id: str | None = None,
          max_shard_bytes: int | None = None) -> dict:
    """Compact parts (or re-shard existing shards) and write meta/ and the card."""
    out = Path(out)
    if config is None:
        existing = _existing_config(out)
        if existing is None:
            raise FileNotFoundError(f"{out} holds no orbitdata dataset (no parts/plan.json or meta/info.json)")
        config = GenerationConfig.from_dict(existing, where=f"{out} config")
    if max_shard_bytes is not None:
        config = config.replace(dataset={"max_shard_bytes": int(max_shard_bytes)})
    ds = config.dataset
    storage = StorageSettings(ds.compression, ds.row_group_rows, ds.max_shard_bytes)
    result = write_shards(out, storage)
    write_json(out, S.STATS_PATH, result.stats)
    sizes = {S.DATA_DIR: {}, S.EPISODES_DIR: {}}
    for rel in result.files:
        folder, name = rel.split("/")
        split = name.split("-")[0]
        sizes[folder][split] = sizes[folder].get(split, 0) + (out / rel).stat().st_size
    files = result.files + [S.STATS_PATH]
    info = build_info(config, result.episodes, out, files)
    overview = _write_overview(out, result.episodes)
    if overview:
        files.append(overview)
    card = render_card(info, config, sizes, repo=repo_id or out.name, overview=overview)
    atomic_write(out / S.CARD_PATH, card.encode())
    info = build_info(config, result.episodes, out, files + [S.CARD_PATH])
    write_json(out, S.INFO_PATH, info)  # last: its presence means the layout is complete
    if parts.parts_dir(out).exists():
        shutil.rmtree(parts.parts_dir(out))
    return info
