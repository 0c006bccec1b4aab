"""``orbitmodel depth``: refit a run's depth head for the planner (near cells weighted)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitmodel.cli.errors import fail, friendly, positive
from orbitmodel.cli.threads import Threads, use_threads
from orbitmodel.data import EVAL_SPLITS
from orbitmodel.plan.depth_recipe import DepthRefitConfig, ImaginedDepthConfig, check_head_name

_D = DepthRefitConfig()
_I = ImaginedDepthConfig()


def register(app: typer.Typer) -> None:
    app.command("depth")(depth)


@friendly
def depth(
    run: Annotated[Path, typer.Argument(help="a trained Stage I run folder (`orbitmodel train --out RUN`)")],
    dataset: Annotated[str, typer.Argument(help="the run's orbitdata dataset (train split fitted, test split scored)")],
    frames: Annotated[
        Optional[int],
        typer.Option(
            min=1,
            help=f"random training frames encoded once [default: {_D.frames}]; with --imagined, windows "
            f"imagined once [default: {_I.windows}]",
        ),
    ] = None,
    test_frames: Annotated[
        Optional[int],
        typer.Option(
            min=1,
            help=f"random test frames for the before/after table [default: {_D.test_frames}]; with "
            f"--imagined, windows [default: {_I.test_windows}]",
        ),
    ] = None,
    epochs: Annotated[int, typer.Option(min=1)] = _D.epochs,
    lr: Annotated[float, typer.Option(callback=positive, help="learning rate, above 0")] = _D.lr,
    near_weight: Annotated[
        float, typer.Option(min=0.0, help="extra loss weight of cells nearer than --near-m")
    ] = _D.near_weight,
    near_m: Annotated[float, typer.Option(callback=positive, help="metres: the planner's range, above 0")] = _D.near_m,
    seed: Annotated[int, typer.Option(min=0)] = _D.seed,
    eval_split: Annotated[
        str,
        typer.Option(
            help="frames the before/after table scores: test (to report) or val, "
            "the run's validation episodes (to choose a recipe)"
        ),
    ] = _D.eval_split,
    imagined: Annotated[
        bool,
        typer.Option(
            help="fit the head that reads depth from the world model's imagined latents instead "
            "(RUN/depth-imagined; the planner's --set obstacle_motion=imagined)"
        ),
    ] = False,
    name: Annotated[
        str,
        typer.Option(
            help="write the head to RUN/depth-NAME instead, beside the run's own (the planner's "
            "--set depth_head=NAME): e.g. dynamic, refitted on the dynamic tier's frames"
        ),
    ] = "",
    overwrite: Annotated[bool, typer.Option(help="replace the head already there")] = False,
    threads: Threads = None,
) -> None:
    """Refit the depth head on the frozen encoder with near cells weighted (written to RUN/depth).

    Stage I's depth loss is mostly about the sky; the planner needs the obstacles within its
    range. The latents, and so the dynamics and the probe, are untouched. `orbitmodel eval
    closed-loop` uses RUN/depth when it is there (`--set depth_head=stage1` for the Stage I head).
    """
    use_threads(threads)
    if eval_split not in EVAL_SPLITS:
        fail(f"--eval-split {eval_split}: choose one of {', '.join(EVAL_SPLITS)}")
    if name:
        if imagined:
            fail("--name names a refit of the current frame's head; drop it with --imagined (RUN/depth-imagined)")
        try:
            check_head_name(name)
        except ValueError as err:
            fail(f"--name: {err}")
    recipe = dict(epochs=epochs, lr=lr, near_weight=near_weight, near_m=near_m, seed=seed, eval_split=eval_split)
    if imagined:
        cfg = ImaginedDepthConfig(windows=frames or _I.windows, test_windows=test_frames or _I.test_windows, **recipe)
        _imagined(run, dataset, cfg, overwrite)
        return
    from orbitmodel.plan.depth_bands import comparison_lines
    from orbitmodel.plan.depth_refit import depth_folder, refit_depth_head

    cfg = DepthRefitConfig(frames=frames or _D.frames, test_frames=test_frames or _D.test_frames, **recipe)
    result = refit_depth_head(run, dataset, cfg, overwrite=overwrite, name=name)
    for line in comparison_lines(result):
        typer.echo(line)
    s = result["seconds"]
    typer.echo(f"encoded in {s['encode']:.0f} s, fitted in {s['fit']:.0f} s; wrote {depth_folder(run, name)}")


def _imagined(run: Path, dataset: str, cfg: ImaginedDepthConfig, overwrite: bool) -> None:
    """``orbitmodel depth --imagined``: the head on imagined latents (``plan.imagined_fit``)."""
    from orbitmodel.plan.imagined_fit import fit_imagined_depth, imagined_folder, step_lines

    result = fit_imagined_depth(run, dataset, cfg, overwrite=overwrite)
    for line in step_lines(result):
        typer.echo(line)
    s = result["seconds"]
    typer.echo(f"imagined in {s['imagine']:.0f} s, fitted in {s['fit']:.0f} s; wrote {imagined_folder(run)}")
