"""Entry point: ``orbitmodel COMMAND``. Each command lives in its own module."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="orbitmodel",
    help="Train Orbit-Planner's latent world model on an orbitdata dataset, probe it, plan with it, evaluate it.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
eval_app = typer.Typer(help="Measure a trained run: latent rollouts, the physics probe, closed-loop flight.",
                       no_args_is_help=True)
app.add_typer(eval_app, name="eval")


@app.command("presets")
def presets() -> None:
    """List the model presets with their sizes."""
    from orbitmodel.config import PRESETS
    from orbitmodel.model.world_model import WorldModel

    for name, factory in PRESETS.items():
        p = factory()
        m = p.model
        typer.echo(f"{name:6s} {WorldModel(m).num_parameters() / 1e6:6.2f}M params  {m.image_size} px, "
                   f"patch {m.patch_size}, ViT {m.depth}x{m.width}, latent {m.latent_dim}, "
                   f"predictor {m.pred_depth}x{m.latent_dim}; window {p.train.window}, batch {p.train.batch_size}"
                   f"\n       {p.description}")


def _register() -> None:
    from orbitmodel.cli import closed_loop, depth, evaluate, policy, probe, train

    train.register(app)
    evaluate.register(eval_app)
    policy.register(app, eval_app)
    closed_loop.register(eval_app)
    probe.register(app, eval_app)
    depth.register(app)


_register()


def main() -> None:
    app()


if __name__ == "__main__":
    main()
