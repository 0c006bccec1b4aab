"""``orbitmodel train-policy`` and ``orbitmodel eval policy``: the Diffusion Policy baseline."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitmodel.baselines.diffusion.config import POLICY_PRESETS
from orbitmodel.cli.errors import friendly, positive
from orbitmodel.cli.threads import Threads, use_threads
from orbitmodel.cli.train import Device, Level, Outcome, echo_trained

PolicyPresetName = Enum("PolicyPresetName", {name: name for name in POLICY_PRESETS}, type=str)
Split = Enum("Split", {"test": "test", "val": "val", "train": "train"}, type=str)


def register(app: typer.Typer, eval_app: typer.Typer) -> None:
    app.command("train-policy")(train_policy)
    eval_app.command("policy")(eval_policy)
    eval_app.command("expert-floor")(eval_expert_floor)


@friendly
def train_policy(
    dataset: Annotated[str, typer.Argument(help="orbitdata dataset folder")],
    out: Annotated[Path, typer.Option("--out", help="run folder to write (checkpoints, metrics, config)")],
    preset: Annotated[
        PolicyPresetName,
        typer.Option(
            help="policy size and recipe: cpu; cpu-state (no camera: states and goal); cpu-state-obstacles (a "
            "privileged diagnostic told the true obstacles, scored open loop only); tiny (tests)"
        ),
    ] = "cpu",
    epochs: Annotated[Optional[int], typer.Option(min=1, help="epochs (default: the preset's)")] = None,
    max_steps: Annotated[
        Optional[int], typer.Option(min=0, help="stop after this many steps (0 = epochs only)")
    ] = None,
    pad_before: Annotated[
        Optional[int],
        typer.Option(min=0, help="windows per episode that start before its first frame [default: the preset's, 1]"),
    ] = None,
    mask_padding: Annotated[
        Optional[bool],
        typer.Option(
            help="no loss on the terminal frame and the padding past an episode's end [default: the preset's, on; a run "
            "made before this option resumes with --pad-before 0 --no-mask-padding]"
        ),
    ] = None,
    val_fraction: Annotated[
        Optional[float],
        typer.Option(
            min=0.0,
            max=0.99,
            help="hold this seeded fraction of the train episodes out, for choices (eval policy "
            "--split val) [default: the preset's, 0]",
        ),
    ] = None,
    batch_size: Annotated[Optional[int], typer.Option(min=1, help="windows per step and process")] = None,
    lr: Annotated[Optional[float], typer.Option(callback=positive, help="peak learning rate, above 0")] = None,
    level: Annotated[
        Optional[list[Level]],
        typer.Option("--level", "--levels", help="train on these levels (repeatable; default: expert)"),
    ] = None,
    outcome: Annotated[Optional[list[Outcome]], typer.Option(help="train on these outcomes only (repeatable)")] = None,
    workers: Annotated[Optional[int], typer.Option(min=0, help="DataLoader worker processes")] = None,
    seed: Annotated[
        Optional[int], typer.Option(min=0, help="data order, noise, augmentation and initialisation")
    ] = None,
    device: Annotated[Device, typer.Option(help="auto = CUDA when available")] = "auto",
    resume: Annotated[bool, typer.Option(help="continue the run in --out from its latest checkpoint")] = False,
    overwrite: Annotated[bool, typer.Option(help="replace a run already in --out")] = False,
    extend: Annotated[
        bool,
        typer.Option(
            help="with --resume and a larger --max-steps: train a run on past its end (the learning rate follows the "
            "longer schedule from the checkpoint on)"
        ),
    ] = False,
    threads: Threads = None,
) -> None:
    """Train a Diffusion Policy on the dataset's expert episodes.

    The baseline of Chi et al. (2023): it sees the last 2 camera images (none for --preset cpu-state)
    and states and the goal in the body frame, predicts 16 actions and executes 8. Multi-GPU:
    `torchrun --nproc_per_node N -m orbitmodel.cli.app train-policy ...`.
    """
    use_threads(threads)
    from orbitmodel.baselines.diffusion.config import get_policy_preset
    from orbitmodel.baselines.diffusion.train import DEFAULT_LEVELS, PolicyRequest
    from orbitmodel.baselines.diffusion.train import train_policy as train

    p = get_policy_preset(preset.value).with_train(
        epochs=epochs,
        max_steps=max_steps,
        batch_size=batch_size,
        lr=lr,
        val_fraction=val_fraction,
        pad_before=pad_before,
        mask_padding=mask_padding,
        num_workers=workers,
        seed=seed,
    )
    req = PolicyRequest(
        dataset=dataset,
        preset=p,
        out=out,
        levels=tuple(dict.fromkeys(x.value for x in level)) if level else DEFAULT_LEVELS,
        outcomes=tuple(o.value for o in outcome or ()),
        device=device.value,
        resume=resume,
        overwrite=overwrite,
        extend=extend,
    )
    echo_trained("the policy", train(req), out)


def _sampling(preset: str | None, sets: list[str] | None):
    """(PolicySampling, preset name) from ``--preset`` and ``--set KEY=VALUE`` (default preset: cpu)."""
    from orbitdata.cli.options import key_values
    from orbitmodel.baselines.diffusion.sampling import DEFAULT_FLIGHT, policy_sampling

    preset = preset or DEFAULT_FLIGHT
    return policy_sampling(preset, **key_values(sets or [], "--set", "draws=4")), preset


@friendly
def eval_policy(
    run: Annotated[Path, typer.Argument(help="policy run folder (from `orbitmodel train-policy`)")],
    dataset: Annotated[str, typer.Argument(help="orbitdata dataset folder with held-out windows")],
    split: Annotated[
        Split,
        typer.Option(
            help="test (to report), val: the run's validation episodes (to choose), or train (how well it fits)"
        ),
    ] = "test",
    level: Annotated[
        Optional[list[Level]],
        typer.Option("--level", "--levels", help="levels to measure on (repeatable; default: expert)"),
    ] = None,
    stride: Annotated[int, typer.Option(min=1, help="frames between window starts")] = 4,
    max_windows: Annotated[int, typer.Option(min=0, help="measure only the first N windows (0 = all)")] = 0,
    batch_size: Annotated[int, typer.Option(min=1, help="windows sampled together")] = 64,
    seed: Annotated[int, typer.Option(min=0, help="sampling noise")] = 0,
    preset: Annotated[
        Optional[str],
        typer.Option(
            help="flight preset to sample with, as eval closed-loop flies it: cpu (the reported flight) or reference "
            "(the reference's sampler)"
        ),
    ] = None,
    set_: Annotated[
        Optional[list[str]],
        typer.Option(
            "--set",
            help="KEY=VALUE: change one sampling setting of the preset, repeatable (draws=N: above 1, the "
            "error splits into the draws' variance and the MSE of their mean; noise_scale, "
            "timestep_spacing, inference_steps, action_steps)",
        ),
    ] = None,
    without_obstacles: Annotated[
        bool,
        typer.Option(help="tell a privileged policy (cpu-state-obstacles) no obstacle: how much it relies on them"),
    ] = False,
    device: Annotated[Device, typer.Option(help="auto = CUDA when available")] = "auto",
    as_json: Annotated[bool, typer.Option("--json", help="print the result as JSON")] = False,
) -> None:
    """Action MSE of the executed actions on held-out windows, beside predicting the mean action."""
    from orbitmodel.baselines.diffusion.evaluate import evaluate_policy
    from orbitmodel.baselines.diffusion.train import DEFAULT_LEVELS
    from orbitmodel.train.loop import resolve_device

    levels = tuple(dict.fromkeys(x.value for x in level)) if level else DEFAULT_LEVELS
    sampling, preset = _sampling(preset, set_)
    result = evaluate_policy(
        run,
        dataset,
        split=split.value,
        levels=levels,
        stride=stride,
        max_windows=max_windows,
        batch_size=batch_size,
        seed=seed,
        device=str(resolve_device(device.value)),
        sampling=sampling,
        without_obstacles=without_obstacles,
        preset=preset,
    )
    samples = sampling.draws
    if as_json:
        typer.echo(json.dumps(result.to_dict()))
        return
    typer.echo(
        f"action MSE on {result.windows} {split.value} windows ({result.frames} frames, {'/'.join(levels)}): "
        f"policy {result.policy:.5f}, mean action {result.mean_action:.5f} (ratio {result.ratio:.3f})"
        + (
            f"; over {samples} draws: variance {result.variance:.5f}, mean of the draws {result.sample_mean:.5f}"
            if samples > 1
            else ""
        )
    )
    for title, rows, label in (
        ("executed index", result.per_index, lambda r: f"t+{r['index']}"),
        (
            "distance to the goal at t",
            result.per_band,
            lambda r: f"{r['from_m']:g}-{r['to_m']:g} m" if r["to_m"] else f">= {r['from_m']:g} m",
        ),
    ):
        typer.echo(f"  by {title}:")
        for r in rows:
            ratio = "-" if r["ratio"] is None else f"{r['ratio']:.3f}"
            typer.echo(
                f"    {label(r):>9}: {r['frames']:6d} frames, ratio {ratio}"
                + (
                    f" (policy {r['policy']:.5f}, mean action {r['mean_action']:.5f}"
                    + (
                        f", variance {r['variance']:.5f}, mean of the draws {r['sample_mean']:.5f}"
                        if samples > 1
                        else ""
                    )
                    + ")"
                    if r["frames"]
                    else ""
                )
            )


@friendly
def eval_expert_floor(
    run: Annotated[Path, typer.Argument(help="policy run folder: its windows, validation episodes and mean action")],
    dataset: Annotated[str, typer.Argument(help="the orbitdata dataset it trained on")],
    split: Annotated[Split, typer.Option(help="test, val (the run's validation episodes) or train")] = "test",
    stride: Annotated[int, typer.Option(min=1, help="frames between window starts")] = 4,
    max_windows: Annotated[int, typer.Option(min=0, help="look at only the first N windows (0 = all)")] = 0,
    plans: Annotated[int, typer.Option(min=1, help="other RRT* plans of each episode's task")] = 64,
    position_m: Annotated[
        float, typer.Option(min=0.0, help="another plan's path passes this close to the state")
    ] = 0.1,
    speed_mps: Annotated[float, typer.Option(min=0.0, help="... with a reference velocity this close")] = 0.1,
    angle_deg: Annotated[float, typer.Option(min=0.0, help="... and a camera attitude this close")] = 27.0,
    policy: Annotated[bool, typer.Option(help="score the policy on the same windows")] = True,
    seed: Annotated[int, typer.Option(min=0, help="the policy's sampling noise")] = 0,
    preset: Annotated[Optional[str], typer.Option(help="the policy's flight preset, as eval policy's")] = None,
    set_: Annotated[
        Optional[list[str]],
        typer.Option("--set", help="KEY=VALUE: change one sampling setting of the preset, as eval policy's"),
    ] = None,
    device: Annotated[Device, typer.Option(help="auto = CUDA when available")] = "auto",
    as_json: Annotated[bool, typer.Option("--json", help="print the result as JSON")] = False,
) -> None:
    """How closely another plan of the expert, at the recorded states, matches the recorded
    actions: the floor under `eval policy`'s error (other plans that could be at frame t act at
    frames t .. t+7), beside the mean action and the policy on the same windows."""
    from orbitmodel.baselines.diffusion.expert_floor import expert_floor
    from orbitmodel.train.loop import resolve_device

    sampling, preset = _sampling(preset, set_) if (policy or preset or set_) else (None, None)
    r = expert_floor(
        run,
        dataset,
        split=split.value,
        stride=stride,
        max_windows=max_windows,
        plans=plans,
        position_m=position_m,
        speed_mps=speed_mps,
        angle_deg=angle_deg,
        with_policy=policy,
        seed=seed,
        device=str(resolve_device(device.value)),
        sampling=sampling,
        preset=preset,
    )
    if as_json:
        typer.echo(json.dumps(r.to_dict()))
        return
    d = r.own_plan_deviation
    deviation = f"{d['position_m'][1]:.2f} m, {d['speed_mps'][1]:.2f} m/s, {d['angle_deg'][1]:.0f} deg"
    typer.echo(
        f"{r.scored_windows} of {r.windows} {split.value} windows have another of {r.plans} plans within "
        f"{r.position_m:g} m, {r.speed_mps:g} m/s, {r.angle_deg:g} deg ({r.plans_per_window:.1f} per window; "
        f"the own plan passes in {r.own_plan_could:.0%}, 90 % of its flights within {deviation}); ratio to "
        f"the mean action over {r.frames} frames: "
        f"another expert {r.ratio:.3f}, own plan {r.own / r.mean_action:.3f}"
        + (f", policy {r.policy['ratio']:.3f}" if r.policy else "")
    )
    bands = r.policy["per_band"] if r.policy else [None] * len(r.per_band)
    for row, mine in zip(r.per_band, bands):
        label = f"{row['from_m']:g}-{row['to_m']:g} m" if row["to_m"] else f">= {row['from_m']:g} m"
        if not row["frames"]:
            typer.echo(f"  {label:>9}: no frames")
            continue
        typer.echo(
            f"  {label:>9}: {row['frames']:6d} frames, another expert {row['other_ratio']:.3f}, own plan "
            f"{row['own_ratio']:.3f}" + (f", policy {mine['ratio']:.3f}" if mine else "")
        )
