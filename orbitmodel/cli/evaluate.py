"""``orbitmodel eval rollout``: the latent rollout and depth evaluation of a Stage I run."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitmodel.cli.errors import friendly


def register(app: typer.Typer) -> None:
    app.command("rollout")(rollout)


@friendly
def rollout(
    run: Annotated[Path, typer.Argument(help="a Stage I run folder (orbitmodel train --out RUN)")],
    dataset: Annotated[str, typer.Argument(help="the orbitdata dataset (its test split is used)")],
    windows: Annotated[int, typer.Option(min=2, help="windows, chosen at random with --seed")] = 100,
    split: Annotated[
        str, typer.Option(help="test (to report) or val: the run's validation episodes (to choose)")
    ] = "test",
    horizon: Annotated[int, typer.Option(min=1, max=200, help="rollout steps")] = 50,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    out: Annotated[Optional[Path], typer.Option(help="folder for rollout.json/.png and depth.png [RUN/eval]")] = None,
) -> None:
    """Latent rollout error vs horizon with persistence and shuffled-action baselines (Fig. 3),
    depth predictions vs ground truth (Fig. 4), and collapse diagnostics."""
    from orbitdata.cli.options import check_out_folder
    from orbitmodel.evaluate.rollout import RolloutEvalConfig, evaluate_rollout, summary_lines, write_rollout_report
    from orbitmodel.runs import local_run_folder

    check_out_folder(out)
    if out is None:
        local_run_folder(run, "eval rollout without --out")  # before minutes of evaluation

    result = evaluate_rollout(
        run,
        dataset,
        RolloutEvalConfig(horizon=horizon, windows=windows, seed=seed, check_h=min(12, horizon), split=split),
    )
    paths = write_rollout_report(result, out or local_run_folder(run, "eval rollout without --out") / "eval")
    for line in summary_lines(result):
        typer.echo(line)
    typer.echo("wrote " + ", ".join(str(p) for p in paths))
