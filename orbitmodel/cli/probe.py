"""``orbitmodel probe`` (Stage II: the physics probe) and ``orbitmodel eval probe`` (Table I, Figure 5)."""

from __future__ import annotations

import time
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitmodel.cli.errors import fail, friendly, positive
from orbitmodel.cli.threads import Threads, use_threads
from orbitmodel.cli.train import Device, echo_trained
from orbitmodel.config import INPUTS, INTEGRATORS
from orbitmodel.extras import MissingExtra

Integrator = Enum("Integrator", {name: name for name in INTEGRATORS}, type=str)
Inputs = Enum("Inputs", {name: name for name in INPUTS}, type=str)
# the probe variants (orbitmodel.probe.variants, imported on use): the run's own, the paper's, the
# thrust-only one and the latent-only candidates
VARIANT_NAMES = ("thrust_probe", "paper_probe", "thrust_only") + tuple(
    f"latent_probe-{tag}-{head}-{loss}"
    for tag in ("change", "z")
    for head in ("frames", "steps")
    for loss in ("inc", "noinc")
)
Variant = Enum("Variant", {name: name for name in VARIANT_NAMES}, type=str)


def register(app: typer.Typer, eval_app: typer.Typer) -> None:
    app.command("probe")(probe)
    eval_app.command("probe")(eval_probe)


@friendly
def probe(
    run: Annotated[Path, typer.Argument(help="a trained Stage I run folder (`orbitmodel train --out RUN`)")],
    dataset: Annotated[str, typer.Argument(help="orbitdata dataset: a local folder or a Hub repo id")],
    state_only: Annotated[
        bool, typer.Option(help="train the state-only reference MLP (RUN/probe-state) instead")
    ] = False,
    variant: Annotated[
        Variant,
        typer.Option(
            help="which of the run's probes (Table I's rows; docs/model.md): thrust_probe is the run's own "
            "(RUN/probe, the planner's); paper_probe reads latents only, integrated as upstream does; "
            "thrust_only reads each step's thrusts, no latent; latent_probe-* are the no-thrust candidates "
            "(z or [z, dz]; per-frame or per-step; with or without the increment loss), chosen by "
            "`eval probe --split val`. Each but thrust_probe trains into RUN/probe-NAME"
        ),
    ] = "thrust_probe",
    epochs: Annotated[
        Optional[int], typer.Option(min=1, help="epochs (default: the probe recipe of the run's preset)")
    ] = None,
    max_steps: Annotated[
        Optional[int], typer.Option(min=0, help="stop after this many steps (0 = epochs only)")
    ] = None,
    batch_size: Annotated[Optional[int], typer.Option(min=1, help="windows per step and process")] = None,
    lr: Annotated[Optional[float], typer.Option(callback=positive, help="peak learning rate, above 0")] = None,
    inputs: Annotated[
        Optional[Inputs],
        typer.Option(
            help="latent+change: the MLP reads [z_k, z_k - z_{k-1}]; latent: z_k alone (upstream) "
            "[default: the probe recipe of the run's preset]"
        ),
    ] = None,
    integrator: Annotated[
        Optional[Integrator],
        typer.Option(
            help="coasting: zero increments hold the world-frame velocity; upstream: p += dp, v += dv "
            "[default: the probe recipe of the run's preset]"
        ),
    ] = None,
    per_frame: Annotated[
        Optional[bool],
        typer.Option(
            help="for a run stepping s > 1 frames: predict every frame's increments from each latent (10 s outputs) "
            "instead of one per latent with the frames between interpolated [default: the probe recipe of the "
            "run's preset]"
        ),
    ] = None,
    loss_weights: Annotated[
        Optional[str],
        typer.Option(help="position,velocity,rot6d,w,fuel MSE weights, e.g. 1,1,1,1,0.1 (default: the recipe's)"),
    ] = None,
    increment_weight: Annotated[
        Optional[float],
        typer.Option(
            min=0.0,
            help="weight of the MSE of the predicted per-step increments against the true ones, added to the "
            "state loss [default: the probe recipe's]",
        ),
    ] = None,
    cache_windows: Annotated[
        Optional[int],
        typer.Option(
            min=0, help="train on this many windows whose latents are imagined once (0 = every step, as upstream)"
        ),
    ] = None,
    context: Annotated[
        Optional[int],
        typer.Option(min=1, help="model steps of context before each window's horizon (default: the probe recipe's)"),
    ] = None,
    max_body_rate: Annotated[
        Optional[float],
        typer.Option(
            min=0.0,
            help="train on the windows whose body rate stays at or below this many rad/s (0 = every window) "
            "[default: the probe recipe's]",
        ),
    ] = None,
    workers: Annotated[Optional[int], typer.Option(min=0, help="DataLoader worker processes")] = None,
    seed: Annotated[Optional[int], typer.Option(min=0, help="data order and initialisation")] = None,
    device: Annotated[Device, typer.Option(help="auto = CUDA when available")] = "auto",
    resume: Annotated[bool, typer.Option(help="continue the probe run from its latest checkpoint")] = False,
    overwrite: Annotated[bool, typer.Option(help="replace a probe already trained in RUN")] = False,
    threads: Threads = None,
) -> None:
    """Train the physics probe on the run's frozen world model (written to RUN/probe).

    Windows of 8 context + 12 horizon frames: the world model imagines the horizon's latents from
    the logged actions, the probe turns them into state increments, integrated from the true
    state at the last context frame; the loss is the MSE of the integrated states.
    """
    use_threads(threads)
    from orbitmodel.probe.model import probe_folder
    from orbitmodel.probe.train import ProbeRequest, run_recipe, train_probe, trained_recipe
    from orbitmodel.probe.variants import FLOWN, VARIANTS, variant_recipe

    kind = "state" if state_only else "latent"
    if state_only and variant.value != FLOWN:
        fail(f"--variant {variant.value}: the state-only reference has no variants; drop --variant or --state-only")
    given = {"inputs": inputs and inputs.value, "integrator": integrator and integrator.value, "per_frame": per_frame}
    given["increment_weight"] = increment_weight
    for key, value in VARIANTS[variant.value].items():  # what makes the variant is not a flag's to change
        if given.get(key) is not None and given[key] != value:
            flag = "--" + key.replace("_", "-")
            fail(f"{flag}: the {variant.value} variant sets {key} to {value}; drop {flag}")
    weights = None
    if loss_weights is not None:
        try:
            weights = tuple(float(w) for w in loss_weights.split(","))
        except ValueError:
            weights = ()
        if len(weights) != 5 or not all(0 <= w < float("inf") for w in weights):  # nan fails the test too
            fail(
                f"--loss-weights {loss_weights!r}: give 5 finite non-negative numbers, position,velocity,rot6d,w,fuel "
                "(e.g. 1,1,1,1,100)"
            )
    base = run_recipe(run) if variant.value == FLOWN else trained_recipe(run)  # a variant changes the run's probe
    recipe = variant_recipe(base, variant.value).with_changes(
        inputs=inputs.value if inputs else None,
        integrator=integrator.value if integrator else None,
        per_frame=per_frame,
        epochs=epochs,
        increment_weight=increment_weight,
        max_steps=max_steps,
        batch_size=batch_size,
        lr=lr,
        weights=weights,
        cache_windows=cache_windows,
        context=context,
        max_body_rate=max_body_rate,
        num_workers=workers,
        seed=seed,
    )
    req = ProbeRequest(
        run=run,
        dataset=dataset,
        recipe=recipe,
        kind=kind,
        device=device.value,
        resume=resume,
        overwrite=overwrite,
        variant=variant.value,
    )
    label = "the state-only probe" if state_only else f"the probe {variant.value}"
    label += " (the run's own)" if variant.value == FLOWN and not state_only else ""
    start = time.perf_counter()
    result = train_probe(req)
    seconds = time.perf_counter() - start
    before = "reading the windows" if state_only else "imagining the windows"
    echo_trained(label, result, probe_folder(run, kind, variant.value), before, seconds)


@friendly
def eval_probe(
    run: Annotated[Path, typer.Argument(help="a Stage I run folder with a trained probe (`orbitmodel probe`)")],
    dataset: Annotated[str, typer.Argument(help="orbitdata dataset whose test split is evaluated")],
    windows: Annotated[int, typer.Option(min=1, help="collision-free test windows, one per episode")] = 100,
    seed: Annotated[int, typer.Option(min=0, help="which episodes and windows")] = 0,
    horizon: Annotated[Optional[list[int]], typer.Option(min=1, help="steps of 0.04 s (repeatable)")] = None,
    out: Annotated[Optional[Path], typer.Option(help="folder for the table and figures (default RUN/eval)")] = None,
    device: Annotated[Device, typer.Option(help="auto = CUDA when available")] = "cpu",
    figures: Annotated[bool, typer.Option(help="write Figure 5 (needs matplotlib)")] = True,
    split: Annotated[
        str, typer.Option(help="test (to report) or val: the run's validation episodes (to choose)")
    ] = "test",
    history: Annotated[
        Optional[int],
        typer.Option(
            min=1,
            help="latents the world model sees per imagined step, as the planner flies it (the cpu planner "
            "preset: 2) [default: the model's own]",
        ),
    ] = None,
    context: Annotated[
        Optional[int],
        typer.Option(
            min=1,
            help="model steps encoded before the horizon, which sets the windows: score probes trained with "
            "other contexts on the same windows [default: the probe's training context]",
        ),
    ] = None,
) -> None:
    """The paper's Table I on the same windows, at the planner's history (2) and the model's: the
    paper's probe (latents only), our best latent-only probe, the run's probe (the planner's), it
    retrained on thrusts alone, the rigid-body model on the logged thrusts and constant velocity,
    each MAE at h = 25 and 50 steps beside the paper's (RUN/eval/table1.json); the run's probe
    beside the state-only MLP at --history (probe_table.json); and Figure 5. On --split val it
    scores the trained latent_probe candidates and records the best (RUN/latent_probe.json)."""
    from orbitdata.cli.options import check_out_folder
    from orbitmodel.probe import table1
    from orbitmodel.probe.evaluate import EvalRequest, evaluate_probe

    check_out_folder(out)  # before minutes of evaluation
    req = EvalRequest(
        run=run,
        dataset=dataset,
        windows=windows,
        seed=seed,
        horizons=tuple(horizon) if horizon else (25, 50),
        out=out,
        device=device.value,
        figures=figures,
        history=history,
        split=split,
        context=context,
    )
    try:
        result = evaluate_probe(req, rigid_body(dataset))
    except MissingExtra as err:
        fail(f"{err}, or pass --no-figures", code=1)
    typer.echo(table1.markdown(result["table1"]))
    typer.echo("wrote " + ", ".join(result["files"]))


def rigid_body(dataset: str):
    """Table I's physics row: the planner's rigid-body model with the dataset's simulator settings
    and all its substeps (MuJoCo's own scheme), as ``(state0 (K, 16), thrusts (K, n, 8)) -> (K, n, 16)``."""
    from orbitdata.load import read_meta
    from orbitmodel.plan.dynamics import RigidBodyDynamics

    sim = read_meta(dataset)[0].generation_config().sim
    return RigidBodyDynamics(sim, substeps=sim.substeps).rollout
