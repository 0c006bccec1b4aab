"""Entry point: ``orbitdata COMMAND``. Each command lives in its own module."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="orbitdata",
    help="Generate, validate, publish and load the Orbit-Planner CubeSat dataset.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _register() -> None:
    from orbitdata.cli import fly, generate

    for module in (generate, fly):
        module.register(app)
    for optional in ("validate", "push", "inspect"):
        try:
            module = __import__(f"orbitdata.cli.{optional}", fromlist=["register"])
        except ModuleNotFoundError as exc:
            if exc.name != f"orbitdata.cli.{optional}":
                raise
            continue
        module.register(app)


_register()


def main() -> None:
    app()


if __name__ == "__main__":
    main()
