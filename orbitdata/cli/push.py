"""``orbitdata push``: validate (quick) and publish a dataset to the Hugging Face Hub."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.filesize import decimal as _size

from orbitdata.cli.errors import fail, friendly, usage_errors
from orbitdata.publish.hub import PushOptions


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly(resumes=True)
    def push(
        folder: Path = typer.Argument(..., help="Dataset folder made by `orbitdata generate`."),
        repo_id: str = typer.Argument(..., help="Hub dataset repo, e.g. user/orbit_planner."),
        private: bool = typer.Option(False, "--private", help="Create the repo private."),
        revision: str = typer.Option(None, "--revision", "--branch", help="Branch to push to (created if missing)."),
        message: str = typer.Option(PushOptions.message, help="Commit message."),
        dry_run: bool = typer.Option(False, "--dry-run", help="List the files and the card; upload nothing."),
        force: bool = typer.Option(False, "--force", help="Push even if validation finds problems."),
    ):
        """Publish a dataset to the Hugging Face Hub, resumably, in several commits.

        Runs `orbitdata validate --quick` first and refuses an invalid dataset unless --force.
        The token comes from HF_TOKEN or `hf auth login`; it is never printed. Run the same
        command again to resume an interrupted push: files already on the Hub are skipped.
        """
        from orbitdata.load.source import check_repo_id, dataset_folder
        from orbitdata.publish import PushRefused, preview
        from orbitdata.publish import push as run
        from orbitdata.validate import ValidateOptions, validate

        with usage_errors(ValueError, FileNotFoundError, NotADirectoryError):
            folder = dataset_folder(folder.expanduser())
            check_repo_id(repo_id)
            if repo_id.count("/") != 1:
                raise ValueError(
                    f"{repo_id!r}: give the repo as NAMESPACE/NAME, e.g. user/orbit_planner "
                    "(the form `load_windows` and `orbitmodel train` read it back by)"
                )
            options = PushOptions(private=private, revision=revision, message=message, force=force)

        from orbitdata.write.meta import card_repo

        shown = card_repo(folder)
        if shown is not None and shown != repo_id:
            typer.echo(
                f"note: the card's loading snippet names {shown!r}; `orbitdata shard {folder} --repo-id {repo_id}` "
                "rewrites it for this repo before the push",
                err=True,
            )
        report = validate(folder, ValidateOptions(quick=True))
        verdict = "valid" if report.ok else f"INVALID ({', '.join(report.failed())})"
        typer.echo(
            f"validate --quick: {verdict} [{report.files} files, {report.episodes} episodes, "
            f"{report.frames} frames, {report.seconds:.1f} s]"
        )
        if not report.ok:
            typer.echo(report.render())
            if not force:
                if not dry_run:
                    fail(f"refusing to push {folder}: fix the problems above, or pass --force to push it anyway")
                typer.echo("(a real push would be refused: fix the problems, or pass --force)")

        if dry_run:
            plan = preview(folder)
            typer.echo(
                f"\ndry run: would push {len(plan.files)} files ({_size(plan.bytes)}) to dataset "
                f"{repo_id} (revision {revision or 'main'}{', private' if private else ''}):"
            )
            width = max(len(f.rel) for f in plan.files)
            for f in plan.files:
                typer.echo(f"  {f.rel:<{width}}  {_size(f.bytes):>10}")
            typer.echo(f"\n--- the card ({(folder / 'README.md').name}) ---")
            typer.echo((folder / "README.md").read_text())
            return

        try:
            result = run(folder, repo_id, options, report=report, log=typer.echo)
        except PushRefused as exc:  # validated above already; kept for API parity
            fail(str(exc))
        n = len(result.uploaded)
        typer.echo(
            f"pushed {n} file(s) ({_size(result.bytes)}) in {len(result.commits)} commit(s) to "
            f"{result.repo_url} (revision {result.revision}); {len(result.unchanged)} unchanged, "
            f"{len(result.deleted)} stale file(s) deleted"
        )
        rev = "" if result.revision == "main" else f", revision={result.revision!r}"
        repo = result.repo_id
        typer.echo(f'load it with: load_dataset("{repo}"{rev}) and load_dataset("{repo}", "episodes"{rev})')
