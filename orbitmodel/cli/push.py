"""``orbitmodel push``: a trained run as a Hugging Face model repo with a generated card."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitmodel.cli.errors import fail, friendly


def register(app: typer.Typer) -> None:
    app.command("push")(push)


@friendly
def push(
    run: Annotated[Path, typer.Argument(help="a run folder: `orbitmodel train` (with its probe) or `train-policy`")],
    repo_id: Annotated[str, typer.Argument(help="the model repo to create or update, e.g. user/orbit-wm-cpu-step5")],
    dry_run: Annotated[bool, typer.Option(help="list the files and print the card; no token, no upload")] = False,
    grid: Annotated[
        Optional[list[Path]],
        typer.Option(
            help="a folder of grid results (eval closed-loop / orbitdata "
            "fly --json), published under eval/grid/FOLDER/ and on the "
            "card (repeatable)"
        ),
    ] = None,
    dataset: Annotated[
        Optional[str],
        typer.Option(
            help="the Hub id of the training dataset, for the card (when the run was trained on a local folder)"
        ),
    ] = None,
    private: Annotated[bool, typer.Option(help="create the repo private")] = False,
    branch: Annotated[Optional[str], typer.Option(help="push to this branch (created from main if missing)")] = None,
    message: Annotated[str, typer.Option(help="commit message")] = "Upload orbitmodel run",
) -> None:
    """Upload RUN to the Hugging Face Hub as model repo REPO_ID: weights (safetensors), configs, the
    probe, state-only reference and refitted depth head, the evaluation files, and a model card
    whose figures are read from them. The token comes from HF_TOKEN or `hf auth login`."""
    from orbitdata.publish.hub import HubError
    from orbitmodel.publish.push import RunPushOptions, plan_push, push_run

    if dataset is not None:
        from orbitdata.load.source import check_repo_id

        try:
            check_repo_id(dataset)
        except ValueError as err:
            fail(f"--dataset: {err}")
    options = RunPushOptions(
        private=private, revision=branch, message=message, grids=tuple(grid or ()), dataset_repo=dataset
    )
    if dry_run:
        plan = plan_push(run, repo_id, options)
        typer.echo(
            f"dry run: {len(plan.files) + 1} file(s), {plan.bytes / 1e6:.2f} MB would go to {repo_id} "
            f"(a {plan.stage} run)"
        )
        for f in plan.files:
            typer.echo(f"  {f.rel}  ({f.bytes / 1e3:.1f} KB)")
        typer.echo(f"  README.md  (the card, below)\n\n{plan.card}")
        return
    try:
        result = push_run(run, repo_id, options, log=typer.echo)
    except HubError as err:
        fail(str(err), code=1)
    typer.echo(
        f"pushed {len(result.files)} file(s) ({result.bytes / 1e6:.2f} MB) to {result.url} (revision "
        f'{result.revision}, commit {result.commit[:12]}); load it with WorldModel.from_pretrained("{result.repo_id}") '
        f"or `orbitmodel eval closed-loop {result.repo_id}`"
    )
