"""``--threads`` for the training commands: how many torch threads the computation takes."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

Threads = Annotated[
    Optional[int],
    typer.Option(min=1, help="torch threads (default: one per core; fewer when other work shares the cores)"),
]


def use_threads(threads: int | None) -> None:
    """Set torch's intra-op threads when ``--threads`` was given; torch's own default otherwise."""
    if threads is not None:
        import torch

        torch.set_num_threads(threads)
