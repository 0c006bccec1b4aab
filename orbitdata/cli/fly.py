"""``orbitdata fly``: fly a pilot over an evaluation grid and print a success table."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table

from orbitdata.cli.errors import friendly, usage
from orbitdata.config import GenerationConfig


def _numbers(text: str, kind, flag: str) -> list:
    try:
        values = [kind(x) for x in text.split(",") if x.strip()]
    except ValueError:
        usage(f"{flag} {text!r} must be a comma-separated list of numbers, e.g. {flag} 1,3,5")
    if not values:
        usage(f"{flag} is empty: the grid needs at least one value, e.g. {flag} 1,3,5")
    return values


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly
    def fly(
        pilot: str = typer.Option("expert", help="expert, risky or exploratory."),
        obstacles: str = typer.Option("1,3,5", help="Obstacle counts, comma-separated."),
        speeds: str = typer.Option("1,2", help="Initial speeds in m/s, comma-separated."),
        episodes: int = typer.Option(20, help="Episodes per setting."),
        seed: int = typer.Option(0, help="Root seed of the grid."),
        json_out: Path = typer.Option(None, "--json", help="Write the table as JSON here."),
        video: Path = typer.Option(None, help="Write a video of each episode to this folder."),
        video_format: str = typer.Option("mp4", help="mp4 or gif."),
        image_size: int = typer.Option(None, help="Camera image size for videos [default: 224]."),
        config: Path = typer.Option(None, help="TOML config (scenario/sim/pilots settings)."),
    ):
        """Fly PILOT over the grid (obstacles x speeds) and print outcome counts per setting."""
        from orbitdata.grid import check_grid, fly_grid, grid_report
        from orbitdata.pilots import PILOTS

        if pilot not in PILOTS:
            usage(f"--pilot {pilot!r} is not one of {', '.join(PILOTS)}")
        n_obst = _numbers(obstacles, int, "--obstacles")
        v = _numbers(speeds, float, "--speeds")
        if episodes < 1:
            usage(f"--episodes {episodes} must be >= 1")
        if seed < 0:
            usage(f"--seed {seed} must be >= 0")
        if video_format not in ("mp4", "gif"):
            usage(f"--video-format {video_format!r} is not one of mp4, gif")
        try:
            check_grid(pilot, n_obst, v, episodes)
        except ValueError as exc:
            usage(str(exc))
        cfg = GenerationConfig.from_toml(config) if config else GenerationConfig()
        if image_size is not None:
            if image_size < 16 or image_size % 16:
                usage(f"--image-size {image_size} must be a positive multiple of 16")
            import dataclasses

            cfg = cfg.replace(sim={"camera": dataclasses.replace(cfg.sim.camera, image_size=image_size)})
        total = len(n_obst) * len(v) * episodes
        console = Console(stderr=True)
        with Progress(TextColumn(f"[bold]fly {pilot}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                      console=console) as bar:
            task = bar.add_task("fly", total=total)
            cells = fly_grid(pilot, n_obst, v, episodes, seed, cfg, video, f".{video_format}",
                             on_episode=lambda cell, outcome: bar.advance(task))
        table = Table(title=f"{pilot} pilot, {episodes} episodes per setting, seed {seed}")
        for col in ("obstacles", "v0 m/s", "success", "collision", "timeout", "out of fuel", "success %"):
            table.add_column(col, justify="right")
        for c in cells:
            table.add_row(str(c.obstacles), f"{c.speed:g}", str(c.success), str(c.collision), str(c.timeout),
                          str(c.out_of_fuel), f"{100 * c.success_rate:.0f}")
        Console().print(table)
        if json_out is not None:
            json_out.parent.mkdir(parents=True, exist_ok=True)
            json_out.write_text(json.dumps(grid_report(pilot, seed, cells), indent=2) + "\n")
