"""``orbitdata generate`` and ``orbitdata shard``."""

from __future__ import annotations

import dataclasses
import os
from enum import Enum
from pathlib import Path

import typer

from orbitdata.cli.errors import friendly, usage, usage_errors
from orbitdata.config import DatasetConfig
from orbitdata.schema import INFO_PATH
from orbitdata.sim.config import CameraConfig

MB = 1_000_000


class Executor(str, Enum):
    local = "local"
    ray = "ray"


class Tier(str, Enum):
    static = "static"
    dynamic = "dynamic"


def load_config(path: Path | None, tier: "Tier | None"):
    """The GenerationConfig of ``--config`` (or the defaults) in ``--tier``'s scenario tier; a file
    that names another tier is a usage error naming both."""
    from orbitdata.config import GenerationConfig, TierConflict

    name = None if tier is None else tier.value
    try:
        if path is not None:
            return GenerationConfig.from_toml(path, name)
        return GenerationConfig() if name is None else GenerationConfig.for_tier(name)
    except TierConflict as exc:
        usage(f"--tier {name} contradicts --config: {exc}; drop one of them or make them agree")


TIER_HELP = "Scenario tier: static (the paper's scenes) or dynamic (drifting debris, CW terms, faults, noisy sensing)."


def _progress_bar(console):
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return Progress(
        TextColumn("[bold]generate"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} episodes"),
        TextColumn("{task.fields[eps]:.2f} ep/s"),
        TextColumn("{task.fields[fps]:.0f} frames/s"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=console,
        disable=not console.is_terminal,
    )


def _below_one(value: float | None) -> float | None:
    """--test-fraction's upper end is open (a test split of every episode leaves none to train)."""
    if value is not None and value >= 1.0:
        raise typer.BadParameter(f"{value:g} must be less than 1")
    return value


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly(resumes=True)
    def generate(
        out: Path = typer.Argument(..., help="Output folder (a Hugging Face dataset layout)."),
        episodes: int = typer.Option(None, min=1, show_default=str(DatasetConfig.episodes), help="Number of episodes."),
        test_fraction: float = typer.Option(
            None,
            min=0.0,
            callback=_below_one,
            show_default=str(DatasetConfig.test_fraction),
            help="Share of each level in the test split: at least 0, below 1.",
        ),
        image_size: int = typer.Option(
            None,
            min=16,
            show_default=str(CameraConfig.image_size),
            help="Square image size in pixels, a multiple of 16.",
        ),
        seed: int = typer.Option(None, min=0, show_default=str(DatasetConfig.seed), help="Root seed."),
        workers: int = typer.Option(0, min=0, help="Worker processes; 0 = all cores."),
        executor: Executor = typer.Option(Executor.local, help="Process pool here, or Ray tasks."),
        ray_address: str = typer.Option(None, help="Ray cluster address (with --executor ray)."),
        max_shard_mb: int = typer.Option(
            None, min=1, show_default=str(DatasetConfig.max_shard_bytes // MB), help="Max data shard size in MB."
        ),
        tier: Tier = typer.Option(None, show_default="static, or the --config's", help=TIER_HELP),
        config: Path = typer.Option(None, help="TOML file with any scenario/sim/pilots/dataset setting."),
        overwrite: bool = typer.Option(False, help="Replace a dataset generated with a different config."),
        repo_id: str = typer.Option(None, help="Repo id to show in the card's loading snippet."),
    ):
        """Generate the dataset (default: the paper's 8000 episodes, 7200 train / 800 test).

        Interrupted runs resume: run the same command again.
        """
        from rich.console import Console

        from orbitdata.viz import overview_figure
        from orbitdata.write.generate import UnusableOutput
        from orbitdata.write.generate import generate as run

        given = {"image_size": image_size, "test_fraction": test_fraction, "episodes": episodes}
        with usage_errors(flags={f: "--" + f.replace("_", "-") for f, v in given.items() if v is not None}):
            if ray_address and executor.value != "ray":
                raise ValueError(f"--ray-address {ray_address} is for Ray tasks: add --executor ray, or drop it")
            if executor.value == "ray":
                from orbitdata.write.executors import check_ray_address

                check_ray_address(ray_address)
            cfg = load_config(config, tier)
            flags = {
                "episodes": episodes,
                "test_fraction": test_fraction,
                "seed": seed,
                "max_shard_bytes": None if max_shard_mb is None else max_shard_mb * MB,
            }
            dataset = {key: value for key, value in flags.items() if value is not None}
            if dataset:
                cfg = cfg.replace(dataset=dataset)
            if image_size is not None:
                cfg = cfg.replace(sim={"camera": dataclasses.replace(cfg.sim.camera, image_size=image_size)})
        workers = workers or os.cpu_count() or 1
        out = out.expanduser()
        if out.exists() and not os.access(out, os.W_OK):
            usage(f"{out} is not writable; choose another OUT or fix its permissions")
        console = Console(stderr=True)
        bar = _progress_bar(console)
        task = bar.add_task("generate", total=cfg.dataset.episodes, eps=0.0, fps=0.0)
        last_logged = [-1]

        def report(p):
            elapsed = max(p.elapsed, 1e-9)
            eps, fps = p.episodes_new / elapsed, p.frames_done / elapsed
            bar.update(task, completed=p.episodes_done, eps=eps, fps=fps)
            # Without a terminal (CI, nohup, a log file) print a line every 5 %.
            step = p.episodes_done * 20 // p.episodes_total
            if not console.is_terminal and step > last_logged[0]:
                last_logged[0] = step
                eta = (p.episodes_total - p.episodes_done) / max(eps, 1e-9)
                console.print(
                    f"generate: {p.episodes_done}/{p.episodes_total} episodes, {eps:.2f} ep/s, "
                    f"{fps:.0f} frames/s, ETA {eta:.0f} s",
                    highlight=False,
                )

        def stamp() -> int | None:  # meta/info.json is written last, once per finished generation
            path = out / INFO_PATH
            return path.stat().st_mtime_ns if path.is_file() else None

        before = stamp()
        with bar, usage_errors(UnusableOutput):  # OUT is a file, holds something else, or is read-only
            info = run(
                out,
                cfg,
                workers=workers,
                executor=executor.value,
                ray_address=ray_address,
                overwrite=overwrite,
                progress=report,
                repo_id=repo_id,
                figure=overview_figure,
                notice=lambda line: console.print(line, highlight=False, markup=False),
            )
            bar.update(task, completed=cfg.dataset.episodes)
        n, frames = info.counts["episodes"], info.counts["frames"]
        if before is not None and stamp() == before:
            typer.echo(f"{out} holds these {n} episode{'s' * (n != 1)} already ({frames} frames): nothing to do")
        else:
            typer.echo(f"wrote {n} episode{'s' * (n != 1)} ({frames} frames) to {out}")
        if "test" not in info.counts["splits"] and cfg.dataset.test_fraction > 0:
            typer.echo(
                "note: no test split: one episode is all train; pass --episodes 2 or more for a test split", err=True
            )

    @app.command()
    @friendly
    def shard(
        folder: Path = typer.Argument(..., help="A generated dataset folder (parts or shards)."),
        max_shard_mb: int = typer.Option(None, min=1, help="Max data shard size in MB [default: the dataset's]."),
        repo_id: str = typer.Option(
            None, help="Repo id to show in the card's loading snippet [default: the card's, else the folder's name]."
        ),
    ):
        """Compact part files, or re-shard a dataset, into data/ and episodes/ shards with meta/ and the card."""
        from orbitdata import schema as S
        from orbitdata.load.source import local_folder
        from orbitdata.viz import overview_figure
        from orbitdata.write.finalize import NoDataset, finalize

        with usage_errors(FileNotFoundError, NotADirectoryError):
            folder = local_folder(folder, repo_ok=False)
        with usage_errors(NoDataset):
            info = finalize(
                folder,
                repo_id=repo_id,
                max_shard_bytes=None if max_shard_mb is None else max_shard_mb * MB,
                figure=overview_figure,
            )
        shards = [rel for rel in info.files if S.SHARD_RE.match(rel)]
        typer.echo(f"sharded {info.counts['episodes']} episodes into {len(shards)} files in {folder}")
