"""``orbitmodel train``: Stage I, the latent world model."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitdata import schema as S
from orbitmodel.cli.errors import friendly, positive
from orbitmodel.cli.threads import Threads, use_threads
from orbitmodel.config import PRESETS

Preset = Enum("Preset", {name: name for name in PRESETS}, type=str)
Level = Enum("Level", {name: name for name in S.LEVELS}, type=str)
Outcome = Enum("Outcome", {name: name for name in S.DYNAMIC_OUTCOMES}, type=str)  # any tier's
Device = Enum("Device", {name: name for name in ("auto", "cpu", "cuda")}, type=str)


def register(app: typer.Typer) -> None:
    app.command("train")(train)


def echo_trained(what: str, result, where, before: str = "", seconds: float | None = None) -> None:
    """The one line every training command ends with (``train.loop.FitResult``); ``seconds``: the
    whole command's, when it did more than train (``before``: what, e.g. imagining the windows)."""
    whole = f"; {seconds / 60:.1f} min in all, {before} included" if seconds is not None else ""
    typer.echo(
        f"trained {what} {result.steps} steps in {result.seconds / 60:.1f} min ({result.windows_per_s:.1f} "
        f"windows/s, {100 * result.data_wait:.1f} % waiting for data){whole}; weights in {where}"
    )


@friendly
def train(
    dataset: Annotated[str, typer.Argument(help="orbitdata dataset: a local folder or a Hub repo id")],
    out: Annotated[Path, typer.Option("--out", help="run folder to write (checkpoints, metrics, config)")],
    preset: Annotated[Preset, typer.Option(help="model size and recipe; see `orbitmodel presets`")] = "cpu",
    epochs: Annotated[Optional[int], typer.Option(min=1, help="epochs (default: the preset's)")] = None,
    max_steps: Annotated[
        Optional[int], typer.Option(min=0, help="stop after this many steps (0 = epochs only)")
    ] = None,
    val_fraction: Annotated[
        Optional[float],
        typer.Option(
            min=0.0,
            max=0.99,
            help="hold this seeded fraction of the train episodes out of Stage I, the probe and the "
            "depth refit: the validation split of `eval ... --split val` [default: the preset's, 0]",
        ),
    ] = None,
    batch_size: Annotated[Optional[int], typer.Option(min=2, help="windows per step and process")] = None,
    window: Annotated[
        Optional[int], typer.Option(min=2, help="model steps per training window (default: the preset's)")
    ] = None,
    lr: Annotated[Optional[float], typer.Option(callback=positive, help="peak learning rate, above 0")] = None,
    lambda_sigreg: Annotated[
        Optional[float], typer.Option(min=0.0, help="SIGReg loss weight (default: the preset's)")
    ] = None,
    sigreg_pool: Annotated[
        Optional[bool],
        typer.Option(
            help="SIGReg over every frame of the batch (pool) or per frame over the batch (upstream; default: the preset's)"
        ),
    ] = None,
    frame_step: Annotated[
        Optional[int],
        typer.Option(min=1, help="frames per predictor step (upstream 1; 5 makes a 50-frame plan 10 predictor calls)"),
    ] = None,
    level: Annotated[Optional[list[Level]], typer.Option(help="train on these levels only (repeatable)")] = None,
    outcome: Annotated[Optional[list[Outcome]], typer.Option(help="train on these outcomes only (repeatable)")] = None,
    workers: Annotated[Optional[int], typer.Option(min=0, help="DataLoader worker processes")] = None,
    seed: Annotated[Optional[int], typer.Option(min=0, help="data order, augmentation and initialisation")] = None,
    resize: Annotated[bool, typer.Option(help="resize images to the preset's size while loading")] = False,
    device: Annotated[Device, typer.Option(help="auto = CUDA when available")] = "auto",
    resume: Annotated[bool, typer.Option(help="continue the run in --out from its latest checkpoint")] = False,
    overwrite: Annotated[bool, typer.Option(help="replace a run already in --out")] = False,
    threads: Threads = None,
) -> None:
    """Train the Stage I world model (ViT + AdaLN-Zero predictor + depth head, SIGReg).

    Multi-GPU / multi-node: launch with `torchrun --nproc_per_node N -m orbitmodel.cli.app train ...`.
    """
    use_threads(threads)
    from orbitmodel.config import get_preset
    from orbitmodel.train.stage1 import Stage1Request, train_world_model

    p = get_preset(preset.value).with_model(lambda_sigreg=lambda_sigreg, sigreg_pool=sigreg_pool, frame_step=frame_step)
    p = p.with_train(
        epochs=epochs,
        max_steps=max_steps,
        batch_size=batch_size,
        window=window,
        lr=lr,
        num_workers=workers,
        seed=seed,
        val_fraction=val_fraction,
    )
    req = Stage1Request(
        dataset=dataset,
        preset=p,
        out=out,
        levels=tuple(x.value for x in level or ()),
        outcomes=tuple(o.value for o in outcome or ()),
        resize=resize,
        device=device.value,
        resume=resume,
        overwrite=overwrite,
    )
    echo_trained("the world model", train_world_model(req), out)
