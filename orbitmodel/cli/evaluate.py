"""``orbitmodel eval ...``: measurements of a trained run."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    pass
