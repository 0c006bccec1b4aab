"""``orbitdata info`` and ``orbitdata show``: see what a dataset holds."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.console import Console
from rich.filesize import decimal
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from orbitdata.cli.errors import fail, friendly, usage, usage_errors
from orbitdata.cli.options import wide_console
from orbitdata.schema import DYNAMIC_OUTCOMES, FPS, LEVELS, OUTCOMES, SPLITS

SPARK = " ▁▂▃▄▅▆▇█"


def _bytes(n: int | None) -> str:
    return "-" if n is None else decimal(n)


def _spark(counts: list[int]) -> str:
    top = max(counts) if counts else 0
    return "".join(SPARK[0 if not c else max(1, round(8 * c / top))] for c in counts) if top else ""


def _value(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return "-" if v is None else str(v)


def _outcomes(s: dict) -> list[str]:
    """The outcomes to tabulate: the static tier's, and any other that the counts name (its tier's)."""
    named = {o for sc in s["counts"].get("splits", {}).values() for o in sc["outcomes"]}
    return [o for o in DYNAMIC_OUTCOMES if o in OUTCOMES or o in named]


def _counts_table(s: dict) -> Table:
    t = Table(title="Episodes per split, level and outcome", title_justify="left")
    outcomes = _outcomes(s)
    for col in ("split", "level", "episodes", "steps", *(o.replace("_", " ") for o in outcomes), "success %"):
        t.add_column(col, justify="left" if col in ("split", "level") else "right")

    def row(split, level, c, style=None):
        n = c["episodes"]
        rate = f"{100 * c['outcomes'].get('success', 0) / n:.1f}" if n else "-"
        t.add_row(
            split, level, str(n), str(c["frames"]), *(str(c["outcomes"].get(o, 0)) for o in outcomes), rate, style=style
        )

    totals = {"episodes": 0, "frames": 0, "outcomes": {o: 0 for o in outcomes}}
    splits = s["counts"].get("splits", {})
    for split, sc in sorted(splits.items(), key=lambda kv: SPLITS.index(kv[0]) if kv[0] in SPLITS else len(SPLITS)):
        for level in LEVELS:
            if sc["levels"].get(level, {}).get("episodes"):
                row(split, level, sc["levels"][level])
        row(split, "all", sc, style="bold")
        totals["episodes"] += sc["episodes"]
        totals["frames"] += sc["frames"]
        for o in outcomes:
            totals["outcomes"][o] += sc["outcomes"].get(o, 0)
        t.add_section()
    row("all", "all", totals, style="bold")
    return t


def _lengths_table(s: dict) -> Table:
    lengths = s["lengths"]
    edges = lengths["histogram"]["edges"]
    t = Table(title=f"Episode length in frames ({s['dt']} s each)", title_justify="left")
    for col in ("episodes of", "n", "min", "p10", "median", "mean", "p90", "max"):
        t.add_column(col, justify="left" if col == "episodes of" else "right")
    t.add_column(f"histogram {edges[0]:g}..{edges[-1]:g}", justify="left")
    groups = [(f"level {k}", v, lengths["histogram"]["by_level"].get(k)) for k, v in lengths["by_level"].items()]
    groups += [(f"outcome {k}", v, lengths["histogram"]["by_outcome"].get(k)) for k, v in lengths["by_outcome"].items()]
    groups.append(("all", lengths["all"], [sum(x) for x in zip(*lengths["histogram"]["by_level"].values())]))
    for name, st, hist in groups:
        t.add_row(
            name,
            str(st["episodes"]),
            *(_value(st[k]) for k in ("min", "p10", "median", "mean", "p90", "max")),
            f"[cyan]{_spark(hist)}[/cyan]" if hist else "",
            style="bold" if name == "all" else None,
        )
    return t


def _sizes_table(s: dict) -> Table:
    sizes = s["sizes"]
    t = Table(title="Sizes", title_justify="left")
    t.add_column("what")
    t.add_column("bytes", justify="right")
    for folder in ("data", "episodes"):
        for split, n in sorted(sizes[folder].items(), reverse=True):
            t.add_row(f"{folder}/{split}-*.parquet", _bytes(n))
    for rel, n in sizes["other"].items():
        t.add_row(rel, _bytes(n))
    t.add_row(f"total ({sizes['files']} files)", _bytes(sizes["total"]), style="bold")
    t.add_row("per step", _bytes(sizes["bytes_per_frame"]))
    return t


def _params_table(s: dict) -> Table:
    t = Table(title="How it was made (the config in meta/info.json)", title_justify="left")
    for col in ("section", "group", "parameters"):
        t.add_column(col, no_wrap=col != "parameters")
    for section, params in s["parameters"].items():
        groups: dict[str, list[str]] = {}
        for name, value in params.items():
            group, _, key = name.rpartition(".")
            groups.setdefault(group, []).append(f"{key}={_value(value).replace(', ', ',')}")
        for i, (group, items) in enumerate(groups.items()):
            t.add_row(section if i == 0 else "", group, Text(" · ".join(items)))
        t.add_section()
    return t


def print_summary(s: dict, console: Console) -> None:
    console.print(f"[bold]{escape(s['source'])}[/bold]")
    console.print(
        f"{s.get('tier', 'static')} tier · schema {s['schema_version']} · {s['codebase_version']} · "
        f"{s['fps']} fps (dt {s['dt']} s) · "
        f"{s['image_size']} px camera · root seed {s['root_seed']}"
    )
    console.print(f"{s['episodes']} episodes · {s['steps']} steps · {_bytes(s['sizes']['total'])}\n")
    for table in (_counts_table(s), _lengths_table(s), _sizes_table(s), _params_table(s)):
        console.print(table)
        console.print()


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly
    def info(
        source: str = typer.Argument(..., help="A dataset folder, or a Hugging Face Hub dataset repo id (user/name)."),
        as_json: bool = typer.Option(False, "--json", help="Print the same summary as JSON."),
    ):
        """Summarise a dataset: counts per split, level and outcome; lengths; sizes; parameters.

        A repo id downloads only meta/info.json and the episodes shards (no frames).
        """
        from orbitdata.load.source import dataset_folder, local_folder
        from orbitdata.load.summary import summarize

        with usage_errors(FileNotFoundError, NotADirectoryError):  # neither a dataset folder nor a repo id
            if local_folder(source) is not None:
                dataset_folder(source)
        summary = summarize(source)
        if as_json:
            typer.echo(json.dumps(summary, indent=2))
        else:
            print_summary(summary, wide_console())

    @app.command()
    @friendly
    def show(
        folder: Path = typer.Argument(..., help="A dataset folder made by `orbitdata generate`."),
        episode: int = typer.Option(
            None, "--episode", "-e", help="Episode index (episode_index, unique across splits)."
        ),
        out: Path = typer.Option(
            ..., "--out", "-o", help="FILE.mp4 or FILE.gif (a video) or FILE.png (a contact sheet)."
        ),
        fps: float = typer.Option(float(FPS), help=f"Video frame rate; the data is {FPS} fps (real time)."),
    ):
        """Render one episode: camera and depth, top and side views of the path, speed, clearance, thrust, fuel.

        Needs the plotting extra: pip install 'orbitdata[viz]'.
        """
        from orbitdata.cli.options import check_report_path
        from orbitdata.load.episodes import EpisodeNotFound, index_range
        from orbitdata.load.source import dataset_folder
        from orbitdata.viz.show import check_format
        from orbitdata.viz.video import check_fps

        out = out.expanduser()  # `--out=~/ep.gif` reaches us unexpanded
        with usage_errors():
            check_format(out)
            check_report_path(out, "--out")
            check_fps(fps, "--fps")
        with usage_errors(FileNotFoundError, NotADirectoryError):
            folder = dataset_folder(folder)
        if episode is None:
            usage(f"pass --episode N: {folder} holds {index_range(folder)}")
        try:
            from orbitdata.viz.show import show_episode

            path = show_episode(folder, episode, out, fps)
        except EpisodeNotFound as exc:
            usage(str(exc))
        except ImportError as exc:
            fail(str(exc))
        typer.echo(f"wrote {path}")
