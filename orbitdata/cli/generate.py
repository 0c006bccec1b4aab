"""``orbitdata generate`` and ``orbitdata shard``."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from orbitdata.cli.errors import friendly, usage
from orbitdata.config import GenerationConfig


def _progress_bar(console: Console) -> Progress:
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


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly
    def generate(
        out: Path = typer.Argument(..., help="Output folder (a Hugging Face dataset layout)."),
        episodes: int = typer.Option(None, help="Number of episodes [default: 8000]."),
        test_fraction: float = typer.Option(None, help="Share of each level in the test split [default: 0.1]."),
        image_size: int = typer.Option(None, help="Square image size in pixels, a multiple of 16 [default: 224]."),
        seed: int = typer.Option(None, help="Root seed [default: 0]."),
        workers: int = typer.Option(0, help="Worker processes; 0 = all cores."),
        executor: str = typer.Option("local", help="'local' (process pool) or 'ray'."),
        ray_address: str = typer.Option(None, help="Ray cluster address (with --executor ray)."),
        max_shard_size: int = typer.Option(None, help="Max data shard size in MB [default: 500]."),
        config: Path = typer.Option(None, help="TOML file with any scenario/sim/pilots/dataset setting."),
        overwrite: bool = typer.Option(False, help="Replace a dataset generated with a different config."),
        repo_id: str = typer.Option(None, help="Repo id to show in the card's loading snippet."),
    ):
        """Generate the dataset (default: the paper's 8000 episodes, 7200 train / 800 test).

        Interrupted runs resume: run the same command again.
        """
        from orbitdata.dataset.generate import generate as run

        cfg = GenerationConfig.from_toml(config) if config else GenerationConfig()
        dataset = {}
        for flag, key, value, ok in (
            ("--episodes", "episodes", episodes, lambda v: v >= 1),
            ("--test-fraction", "test_fraction", test_fraction, lambda v: 0 <= v < 1),
            ("--seed", "seed", seed, lambda v: v >= 0),
            ("--max-shard-size", "max_shard_bytes", max_shard_size, lambda v: v >= 1),
        ):
            if value is not None:
                if not ok(value):
                    usage(f"{flag} {value} is out of range; see `orbitdata generate --help`")
                dataset[key] = value * 1_000_000 if key == "max_shard_bytes" else value
        if dataset:
            cfg = cfg.replace(dataset=dataset)
        if image_size is not None:
            if image_size < 16 or image_size % 16:
                usage(f"--image-size {image_size} must be a positive multiple of 16 (e.g. 64, 128, 224)")
            cfg = cfg.replace(sim={"camera": dataclasses.replace(cfg.sim.camera, image_size=image_size)})
        if executor not in ("local", "ray"):
            usage(f"--executor {executor!r} is not one of 'local', 'ray'")
        if workers < 0:
            usage(f"--workers {workers} must be >= 0 (0 = all cores)")
        workers = workers or os.cpu_count() or 1
        out = out.expanduser()
        if out.exists() and not os.access(out, os.W_OK):
            raise PermissionError(f"{out} is not writable; choose another OUT or fix its permissions")
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
                console.print(f"generate: {p.episodes_done}/{p.episodes_total} episodes, {eps:.2f} ep/s, "
                              f"{fps:.0f} frames/s, ETA {eta:.0f} s", highlight=False)

        with bar:
            info = run(out, cfg, workers=workers, executor=executor, ray_address=ray_address,
                       overwrite=overwrite, progress=report, repo_id=repo_id)
            bar.update(task, completed=cfg.dataset.episodes)
        c = info["counts"]
        typer.echo(f"wrote {c['episodes']} episodes ({c['frames']} frames) to {out}")

    @app.command()
    @friendly
    def shard(
        folder: Path = typer.Argument(..., help="A generated dataset folder (parts or shards)."),
        max_shard_size: int = typer.Option(None, help="Max data shard size in MB [default: the dataset's]."),
    ):
        """Compact part files, or re-shard a dataset, into data/ and episodes/ shards with meta/ and the card."""
        from orbitdata.dataset.generate import shard as run

        if max_shard_size is not None and max_shard_size < 1:
            usage(f"--max-shard-size {max_shard_size} must be >= 1 (MB)")
        if not folder.is_dir():
            raise FileNotFoundError(f"{folder} is not a folder; pass a dataset made by `orbitdata generate`")
        info = run(folder, max_shard_bytes=None if max_shard_size is None else max_shard_size * 1_000_000)
        typer.echo(f"sharded {info['counts']['episodes']} episodes into {len(info['files']) - 2} files in {folder}")
