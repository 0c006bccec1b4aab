"""``orbitmodel body``: learn the prior a pilot's body inference fits under (RUN/body)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from orbitmodel.cli.errors import friendly
from orbitmodel.cli.threads import Threads, use_threads
from orbitmodel.plan.body_recipe import InferenceConfig

_C = InferenceConfig()


def register(app: typer.Typer) -> None:
    app.command("body")(body)


@friendly
def body(
    run: Annotated[Path, typer.Argument(help="a run trained on the dynamic tier (its held-out episodes are scored)")],
    dataset: Annotated[str, typer.Argument(help="the run's orbitdata dataset (its train split)")],
    steps: Annotated[int, typer.Option(min=1, help="AdamW steps")] = _C.steps,
    frames: Annotated[
        int,
        typer.Option(
            min=1, help="the most history frames a cut shows; flights read at most this many (--set fit_frames)"
        ),
    ] = _C.frames,
    seed: Annotated[int, typer.Option(min=0)] = _C.seed,
    overwrite: Annotated[bool, typer.Option(help="replace the inference already there")] = False,
    threads: Threads = None,
) -> None:
    """Learn a prior over the tier's bodies and faults from its training episodes (RUN/body).

    The pilot's body is still fitted by least squares to its own last frames (`--set body=fitted`);
    with `--set body=inferred` the fit is pulled towards a prior that a small network infers from
    the same history, trained to predict the next 25 frames' changes on the run's training
    episodes. Held-out cuts of the run's validation episodes are scored before and after.
    """
    from orbitmodel.plan.inferred_body import FOLDER, fit_body

    use_threads(threads)
    cfg = InferenceConfig(steps=steps, frames=frames, seed=seed)
    card = fit_body(run, dataset, cfg, overwrite=overwrite, log=typer.echo)
    typer.echo(
        f"held-out prediction error {card['inferred_error']:.4f} against {card['ridge_error']:.4f} for the fit alone; "
        f"wrote {run / FOLDER}"
    )
