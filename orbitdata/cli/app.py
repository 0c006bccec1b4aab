"""Entry point: ``orbitdata COMMAND`` (also ``python -m orbitdata``). Each command lives in its own module."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="orbitdata",
    help="Generate, validate, publish and load the Orbit-Planner CubeSat dataset.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts mean their brackets: [viz], [z, dz], [default: ...]
)


def _register() -> None:
    # Each module imports only light things at the top (typer, configs, the pilot registry);
    # what a command needs (MuJoCo, OMPL, torch, datasets) is imported when it runs.
    from orbitdata.cli import fly, generate, inspect, push, validate

    for module in (generate, fly, validate, push, inspect):
        module.register(app)


_register()


def main() -> None:
    from orbitdata.cli.errors import run_app

    run_app(app)


if __name__ == "__main__":
    main()
