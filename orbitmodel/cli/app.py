"""Entry point: ``orbitmodel COMMAND``. Each command lives in its own module."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="orbitmodel",
    help="Train Orbit-Planner's latent world model on an orbitdata dataset, probe it, plan with it, evaluate it.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts mean their brackets: [viz], [z, dz], [default: ...]
)
eval_app = typer.Typer(
    help="Measure a trained run: latent rollouts, the physics probe, closed-loop flight.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(eval_app, name="eval")


@app.command("presets")
def presets() -> None:
    """List the world-model presets (sizes, frame step, probe recipe), the planner presets and the policy flight presets."""
    from orbitmodel.baselines.diffusion.sampling import DEFAULT_FLIGHT, POLICY_FLIGHTS
    from orbitmodel.config import PRESETS
    from orbitmodel.model.world_model import WorldModel
    from orbitmodel.plan.config import PLANNER_PRESETS, default_planner_preset

    typer.echo("world model (orbitmodel train --preset NAME):")
    width = max(map(len, PRESETS))
    for name, factory in PRESETS.items():
        p = factory()
        m, probe = p.model, p.probe
        typer.echo(
            f"  {name:{width}s} {WorldModel(m).num_parameters() / 1e6:6.2f}M params  {m.image_size} px, "
            f"patch {m.patch_size}, ViT {m.depth}x{m.width}, latent {m.latent_dim}, "
            f"predictor {m.pred_depth}x{m.latent_dim}, {m.frame_step} frame(s) a step; window "
            f"{p.train.window}, batch {p.train.loop.batch_size}, SIGReg {m.lambda_sigreg}"
            + (f", {p.train.val_fraction:.0%} of the train episodes held out" if p.train.val_fraction else "")
            + f"; probe {probe.inputs}, {probe.integrator}"
            + (", per frame" if probe.per_frame else "")
            + f", context {probe.train.context}"
            + (f", windows at or below {probe.train.max_body_rate:g} rad/s" if probe.train.max_body_rate else "")
            + f", {probe.train.loop.epochs} epochs\n  {'':{width}s} {p.description}"
        )
    typer.echo(f"planner (orbitmodel eval closed-loop RUN --preset NAME; default here: {default_planner_preset()}):")
    for name, factory in PLANNER_PRESETS.items():
        c = factory()
        history = c.history or "the model's"
        typer.echo(
            f"  {name:9s} K {c.mppi.samples}, H {c.mppi.horizon} frames, history {history}, "
            f"{c.memory_frames} frames of depth points, support {c.support}"
        )
    typer.echo(f"policy flight (orbitmodel eval closed-loop POLICY_RUN --preset NAME; default: {DEFAULT_FLIGHT}):")
    for name, factory in POLICY_FLIGHTS.items():
        s = factory()
        typer.echo(
            f"  {name:9s} {s.action_steps} actions a chunk, {s.draws} draw(s), DDIM {s.timestep_spacing} "
            f"spacing, noise scale {s.noise_scale:g}, camera {'through the JPEG codec' if s.image_codec else 'raw'}"
        )


def _register() -> None:
    from orbitmodel.cli import body, closed_loop, depth, evaluate, policy, probe, push, train

    train.register(app)
    evaluate.register(eval_app)
    policy.register(app, eval_app)
    closed_loop.register(eval_app)
    probe.register(app, eval_app)
    depth.register(app)
    body.register(app)
    push.register(app)


_register()


def main() -> None:
    import os

    from orbitdata.cli.errors import run_app

    # The loader's `datasets` prints a bar per split it indexes; the commands print their own progress.
    os.environ.setdefault("HF_DATASETS_DISABLE_PROGRESS_BARS", "1")
    run_app(app)


if __name__ == "__main__":
    main()
