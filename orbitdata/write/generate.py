"""``generate``: plan, fly and write a dataset, resumably; then :func:`~orbitdata.write.finalize.finalize` it."""

from __future__ import annotations

import errno
import json
import numbers
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from orbitdata import schema as S
from orbitdata.config import GenerationConfig, config_changes
from orbitdata.info import Info
from orbitdata.load.source import read_info
from orbitdata.version import __version__
from orbitdata.write import parts
from orbitdata.write.executors import check_ray_address, run_local, run_ray
from orbitdata.write.finalize import Figure, existing_config, finalize
from orbitdata.write.plan import plan_units


class UnusableOutput(RuntimeError):
    """OUT cannot take this dataset: it is a file, holds another dataset (or other files) that this
    run would clobber, or cannot be written. The message says which and what to do."""


@dataclass
class Progress:
    """What a progress callback receives after every finished unit."""

    units_done: int
    units_total: int
    episodes_done: int  # including units finished by an earlier, interrupted run
    episodes_new: int  # flown by this run (for rates)
    episodes_total: int
    frames_done: int
    elapsed: float  # seconds since this run started


def _manifest(config: GenerationConfig) -> dict:
    return {"config": config.to_dict(), "schema_version": S.SCHEMA_VERSION, "codebase_version": __version__}


def prepare_output(out: Path, config: GenerationConfig, overwrite: bool) -> bool:
    """Make OUT ready. Returns True if the dataset there is already complete."""
    if out.exists() and not out.is_dir():
        raise UnusableOutput(f"{out} exists and is not a folder; choose another OUT")
    existing = existing_config(out) if out.exists() else None
    mine = json.loads(json.dumps(config.to_dict()))  # tuples -> lists, as stored
    if existing is not None and existing != mine:
        theirs = existing.get("scenario", {}).get("tier", "static")
        if not overwrite and theirs != config.tier:
            raise UnusableOutput(
                f"{out} holds a {theirs}-tier dataset; pass --tier {theirs} to resume it, or choose another OUT"
            )
        if not overwrite:
            changes = config_changes(existing, mine)
            shown = "; ".join(changes[:3]) + (f"; and {len(changes) - 3} more" if len(changes) > 3 else "")
            raise UnusableOutput(
                f"{out} holds a dataset generated with another config ({shown}); give the same flags to resume "
                "it, pass --overwrite to replace it, or choose another OUT"
            )
        clear_output(out)
    elif existing is None and out.exists() and any(out.iterdir()):
        if not overwrite:
            raise UnusableOutput(
                f"{out} is not empty and holds no orbitdata dataset; choose an empty folder or pass --overwrite (overwrite=True in Python)"
            )
        clear_output(out)
    complete = (out / S.INFO_PATH).exists() and not parts.parts_dir(out).exists() and existing == mine
    if not complete:
        try:
            out.mkdir(parents=True, exist_ok=True)
            parts.write_manifest(out, _manifest(config))
        except OSError as exc:
            fix = "free some space there" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else "fix its permissions"
            raise UnusableOutput(f"cannot write to {out} ({exc.strerror}); choose another OUT or {fix}") from None
    return complete


def clear_output(out: Path) -> None:
    """Remove what orbitdata writes in OUT and nothing else: a file of the user's in meta/, or one
    in data/ or episodes/ that is not Parquet, stays (the sharder owns those folders' Parquet files)."""
    if (out / S.PARTS_DIR).is_dir():
        shutil.rmtree(out / S.PARTS_DIR)  # generation scratch space, orbitdata's alone
    for path in out.glob(".tmp-*"):  # an interrupted write of the card
        path.unlink()
    for rel in (S.INFO_PATH, S.STATS_PATH, S.OVERVIEW_PATH, S.CARD_PATH):
        if (out / rel).is_file():
            (out / rel).unlink()
    for folder in (S.DATA_DIR, S.EPISODES_DIR, S.META_DIR):
        if not (out / folder).is_dir():
            continue
        for path in (out / folder).iterdir():
            if S.SHARD_RE.match(f"{folder}/{path.name}") or path.name.startswith(".tmp-"):
                path.unlink()
        if not any((out / folder).iterdir()):
            (out / folder).rmdir()


def generate(
    out: Path,
    config: GenerationConfig,
    workers: int = 1,
    executor: str = "local",
    ray_address: str | None = None,
    overwrite: bool = False,
    progress: Callable[[Progress], None] | None = None,
    repo_id: str | None = None,
    figure: Figure | None = None,
    notice: Callable[[str], None] | None = None,
) -> Info:
    """Generate (or resume) the dataset in ``out`` and finalize it. Returns its ``meta/info.json``.

    ``figure``: draws ``meta/overview.png`` for the card (``orbitdata.viz.overview_figure``);
    ``None``: no figure. ``repo_id``: the Hub repo the card's loading snippet names.
    ``notice``: called with one line for each damaged part file of an earlier, interrupted
    generation, whose unit is generated again (the same seed gives the same bytes).
    """
    out = Path(out)
    if executor not in ("local", "ray"):
        raise ValueError(f"unknown executor {executor!r}; expected 'local' or 'ray'")
    if not isinstance(config, GenerationConfig):
        raise ValueError(
            f"config is a {type(config).__name__}: give a GenerationConfig (GenerationConfig() for the paper's)"
        )
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
        raise ValueError(f"workers={workers!r}: give 1 or more processes")
    if executor == "ray":
        check_ray_address(ray_address or None)  # before anything is written
    if prepare_output(out, config, overwrite):
        return read_info(out)
    parts.remove_temporaries(parts.parts_dir(out))
    units = plan_units(config.dataset)
    for path in parts.drop_damaged(out, [u.name for u in units if parts.is_done(out, u.name)]):
        if notice:
            notice(f"{path} is damaged (Parquet cannot open it): its unit is generated again")
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
    return finalize(out, config, repo_id=repo_id, figure=figure)
