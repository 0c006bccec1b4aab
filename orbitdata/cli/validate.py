"""``orbitdata validate``: check a dataset folder against the contract; exit 0 clean, 1 problems, 2 usage."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from orbitdata.cli.errors import friendly, usage_errors
from orbitdata.validate.report import DEFAULT_CAP


def _progress():
    """A transient bar on stderr when it is a terminal; nothing otherwise (logs, CI, pipes)."""
    if not sys.stderr.isatty():
        return None, None
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    bar = Progress(
        TextColumn("[bold]validate {task.fields[phase]}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    )
    task = bar.add_task("validate", total=None, phase="")

    def update(phase: str, done: int, total: int) -> None:
        bar.update(task, completed=done, total=total, phase=phase)

    return bar, update


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly
    def validate(
        folder: Path = typer.Argument(..., help="Dataset folder, or a downloaded Hub snapshot."),
        quick: bool = typer.Option(False, "--quick", help="Structure, integrity, schema and counts only (no rows)."),
        workers: int = typer.Option(0, min=0, help="Worker processes; 0 = all cores (fewer for small datasets)."),
        json_out: Path = typer.Option(None, "--json", help="Also write a machine-readable report here."),
        max_per_check: int = typer.Option(DEFAULT_CAP, min=1, help="Problems listed per check; the rest are counted."),
    ):
        """Check a dataset against the contract and report every problem, grouped by check.

        Full mode (the default) reads every row and image; --quick reads only metadata, footers
        and the episodes table, and hashes every file. Exit code: 0 clean, 1 problems found,
        2 usage error.
        """
        from orbitdata.cli.options import check_report_path
        from orbitdata.load.source import local_folder
        from orbitdata.validate import ValidateOptions
        from orbitdata.validate import validate as run

        with usage_errors(FileNotFoundError, NotADirectoryError, ValueError):
            folder = local_folder(folder.expanduser(), repo_ok=False)
            if not any((folder / part).exists() for part in ("meta", "data", "episodes")):
                raise FileNotFoundError(
                    f"{folder} is not an orbitdata dataset (no meta/, data/ or episodes/): "
                    "give the folder `orbitdata generate` wrote"
                )
            check_report_path(json_out)  # a folder, or a file where its folder should be
            if json_out is not None and not json_out.expanduser().parent.is_dir():
                raise FileNotFoundError(f"--json {json_out}: folder {json_out.expanduser().parent} does not exist")
        options = ValidateOptions(quick=quick, workers=workers, max_per_check=max_per_check)
        bar, update = _progress()
        if bar is not None:
            with bar:
                report = run(folder, options, progress=update)
        else:
            report = run(folder, options)
        typer.echo(report.render())
        if json_out is not None:
            report.write_json(json_out.expanduser())
            typer.echo(f"JSON report: {json_out}")
        raise typer.Exit(0 if report.ok else 1)
