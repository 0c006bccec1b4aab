"""``orbitdata fly``: fly a pilot over an evaluation grid and print a success table."""

from __future__ import annotations

import inspect
import json
import math
from enum import Enum
from pathlib import Path

import typer

from orbitdata.cli.errors import friendly, usage_errors
from orbitdata.cli.generate import TIER_HELP, Tier, load_config
from orbitdata.cli.options import comma_numbers, key_values, wide_console
from orbitdata.fly.registry import ENTRY_POINT_GROUP, list_pilots
from orbitdata.sim.config import CameraConfig


class VideoFormat(str, Enum):
    mp4 = "mp4"
    gif = "gif"


def _pilot(name: str) -> str:
    # Checked when parsed, against the live registry (a pilot may be registered after import).
    if name not in list_pilots():
        raise typer.BadParameter(f"{name!r} is not one of {', '.join(list_pilots())}")
    return name


def _numbers(kind, flag: str):
    def parse(text: str) -> list:
        try:
            return comma_numbers(text, kind, flag)
        except ValueError as exc:
            raise typer.BadParameter(str(exc).removeprefix(f"{flag} ")) from None

    return parse


def _finite(value: float) -> float:
    if not math.isfinite(value):
        raise typer.BadParameter(f"{value} must be a finite sigma, such as 0.05")
    return value


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly
    def fly(
        pilot: str = typer.Option(
            "expert",
            parser=_pilot,
            help=f"Who flies: {', '.join(list_pilots())}, or any "
            f"pilot an installed package registers (entry points '{ENTRY_POINT_GROUP}').",
        ),
        obstacles: str = typer.Option(
            "1,3,5", parser=_numbers(int, "--obstacles"), help="Obstacle counts, comma-separated."
        ),
        speeds: str = typer.Option(
            "1,2", parser=_numbers(float, "--speeds"), help="Initial speeds in m/s, comma-separated."
        ),
        episodes: int = typer.Option(20, min=1, help="Episodes per setting."),
        seed: int = typer.Option(0, min=0, help="Root seed of the grid."),
        json_out: Path = typer.Option(None, "--json", help="Write the table as JSON here."),
        video: Path = typer.Option(None, help="Write a video of each episode to this folder."),
        video_format: VideoFormat = typer.Option(None, help="Video format (with --video).  [default: mp4]"),
        render: bool = typer.Option(
            None,
            "--render/--no-render",
            show_default=False,
            help="Render the camera [default: when the pilot needs images or --video].",
        ),
        image_size: int = typer.Option(
            None,
            min=16,
            show_default=str(CameraConfig.image_size),
            help="Camera image size in pixels, a multiple of 16.",
        ),
        thrust_noise: float = typer.Option(
            0.0,
            min=0.0,
            callback=_finite,
            help="Add Gaussian noise of this sigma (normalised thrust) to every action the pilot takes.",
        ),
        noise_hold: int = typer.Option(
            1,
            min=1,
            show_default=False,
            help="Redraw the thrust noise every N control steps (8: held per action chunk) [default: every step].",
        ),
        image_codec: bool = typer.Option(
            False,
            "--image-codec/--raw-images",
            show_default=False,
            help="Hand the pilot its camera through the dataset's JPEG codec (the "
            "config's quality), as the dataset stores it [default: raw renders, unless the pilot asks "
            "for the codec, as a policy's flight preset does].",
        ),
        tier: Tier = typer.Option(None, show_default="static, or the --config's", help=TIER_HELP),
        config: Path = typer.Option(None, help="TOML config (scenario/sim/pilots settings)."),
        pilot_option: list[str] = typer.Option([], help="KEY=VALUE passed to the pilot's factory (repeatable)."),
    ):
        """Fly PILOT over the grid (obstacles x speeds) and print outcome counts per setting."""
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
        from rich.table import Table

        from orbitdata.cli.options import check_report_path, check_video_folder
        from orbitdata.fly.grid import check_grid, fly_grid, grid_report, pooled
        from orbitdata.fly.registry import pilot_factory
        from orbitdata.scenario.config import STATIC
        from orbitdata.schema import outcomes
        from orbitdata.write.parts import write_report

        json_out, video = (p.expanduser() if p is not None else None for p in (json_out, video))  # `--json=~/r.json`
        with usage_errors(flags={"image_size": "--image-size"} if image_size is not None else None):
            check_grid(obstacles, speeds, episodes)
            check_report_path(json_out)
            check_video_folder(video)
            if video is not None and render is False:
                raise ValueError(f"--video {video} records the camera: drop --no-render")
            if video is None and video_format is not None:
                raise ValueError(f"--video-format {video_format.value} without --video: give --video FOLDER too")
            cfg = load_config(config, tier)
            if image_size is not None:
                import dataclasses

                cfg = cfg.replace(sim={"camera": dataclasses.replace(cfg.sim.camera, image_size=image_size)})
        options = key_values(pilot_option, "--pilot-option", "checkpoint=run/model.pt")
        factory = pilot_factory(pilot)
        with usage_errors(TypeError):  # an option the pilot's factory does not take
            try:
                inspect.signature(factory).bind(cfg.flight, **options)
            except TypeError as exc:
                raise TypeError(f"--pilot-option: pilot {pilot!r} {exc}") from None
        with usage_errors(ValueError):  # an option value the factory refuses, before anything flies
            built = factory(cfg.flight, **options)
            if render is False and getattr(built, "needs_images", False):
                raise ValueError(f"pilot {pilot!r} reads the camera: drop --no-render")
        image_codec = image_codec or bool(getattr(built, "image_codec", False))  # the flag, or the pilot's own
        recorder = None
        if video is not None:
            from orbitdata.viz.flight import FlightVideos

            recorder = FlightVideos(video, f".{(video_format or VideoFormat.mp4).value}")
        total = len(obstacles) * len(speeds) * episodes
        console = Console(stderr=True)
        with Progress(
            TextColumn(f"[bold]fly {pilot}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=console
        ) as bar:
            task = bar.add_task("fly", total=total)

            def on_episode(cell, k, result):
                if recorder is not None:
                    recorder.episode(cell, k, result)
                bar.advance(task)

            cells = fly_grid(
                lambda _config: built,
                obstacles,
                speeds,
                episodes,
                seed,
                cfg.flight,
                render=render,
                frame_sink=None if recorder is None else recorder.frame,
                on_episode=on_episode,
                image_quality=cfg.dataset.jpeg_quality if image_codec else None,
                thrust_noise=thrust_noise,
                noise_hold=noise_hold,
            )
        where = "" if cfg.tier == STATIC else f", {cfg.tier} tier"
        table = Table(title=f"{pilot} pilot{where}, {episodes} episodes per setting, seed {seed}")
        names = outcomes(cfg.tier)
        for col in ("obstacles", "v0 m/s", *(o.replace("_", " ") for o in names), "success %"):
            table.add_column(col, justify="right")
        for c in cells:
            counts = (str(getattr(c, o)) for o in names)
            table.add_row(str(c.obstacles), f"{c.speed:g}", *counts, f"{100 * c.success_rate:.0f}")
        wide_console().print(table)
        successes, flown = pooled(cells)
        typer.echo(f"pooled: {successes}/{flown} success")
        if json_out is not None:
            json_out.parent.mkdir(parents=True, exist_ok=True)
            name = f"{pilot}+noise{thrust_noise:g}x{noise_hold}" if thrust_noise else pilot  # ThrustNoise's name
            flight = {
                "pilot_options": options,
                "image_codec": image_codec,
                "thrust_noise": thrust_noise,
                "noise_hold": noise_hold,
            }
            report = grid_report(name, seed, cells, flight, cfg.tier)
            write_report(json_out, json.dumps(report, indent=2) + "\n")
