"""``orbitmodel eval closed-loop`` and ``orbitmodel eval figure6``: the planner on the fly grid."""

from __future__ import annotations

import contextlib
import json
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitmodel.cli.errors import fail, first_line, friendly
from orbitmodel.plan.variant import Variant

PilotName = Enum("PilotName", {v.value: v.value for v in Variant}, type=str)
Executor = Enum("Executor", {"local": "local", "ray": "ray"}, type=str)


def register(app: typer.Typer) -> None:
    app.command("closed-loop")(closed_loop)
    app.command("figure6")(figure6)
    app.command("merge")(merge)
    app.command("table")(table)
    app.command("flips")(flips)
    app.command("pool")(pool)
    app.command("factors")(factors)


def _numbers(text: str, kind, flag: str) -> list:
    from orbitdata.cli.options import comma_numbers

    try:
        return comma_numbers(text, kind, flag)
    except ValueError as exc:
        fail(str(exc))


@friendly
def closed_loop(
    run: Annotated[
        Optional[Path],
        typer.Argument(
            help="Stage I run folder (with its probe) or a policy run "
            "(`orbitmodel train-policy`), or the Hub repo id of either "
            "(owner/name[@revision]); optional for the rigid-body oracles"
        ),
    ] = None,
    pilot: Annotated[
        PilotName,
        typer.Option(help="planner, or an oracle (true dynamics and/or obstacles); a policy run flies itself"),
    ] = "planner",
    preset: Annotated[
        Optional[str],
        typer.Option(
            help="the pilot's preset: a planner preset (paper: K 256; cpu: K 32, history 2) or, for a policy run, a "
            "flight preset (cpu: the reported flight; reference: the reference's sampler); `orbitmodel presets` "
            "lists them (default: cpu for a policy; for a planner paper with CUDA, else cpu)"
        ),
    ] = None,
    set_: Annotated[
        Optional[list[str]],
        typer.Option(
            "--set",
            help="KEY=VALUE: change one setting of the preset, repeatable: for a planner a field of "
            "PlannerConfig, MPPIConfig, CostConfig or TrackerConfig (samples=K, horizon, history, depth_head, "
            "margin_per_speed, image_codec, window, ...), for a policy a field of PolicySampling (draws, pick, "
            "action_steps, ensemble, noise_scale, timestep_spacing, inference_steps, image_codec)",
        ),
    ] = None,
    obstacles: Annotated[str, typer.Option(help="obstacle counts, comma-separated")] = "1,3,5",
    speeds: Annotated[str, typer.Option(help="initial speeds in m/s, comma-separated")] = "1,2",
    episodes: Annotated[int, typer.Option(min=1, help="episodes per setting")] = 20,
    seed: Annotated[int, typer.Option(min=0, help="root seed of the grid (as orbitdata fly)")] = 0,
    json_out: Annotated[
        Optional[Path],
        typer.Option(
            "--json",
            help="write the table and every episode here; a cut flight run again continues from the chunks "
            "kept beside it (*.chunks.jsonl)",
        ),
    ] = None,
    max_steps: Annotated[Optional[int], typer.Option(min=2, help="frames per episode at most [default: 300]")] = None,
    threads: Annotated[int, typer.Option(min=1, help="torch threads (1 is fastest for these small batches)")] = 1,
    batch: Annotated[
        int, typer.Option(min=1, help="episodes flown in lockstep, one batched model call per control step")
    ] = 1,
    executor: Annotated[
        Executor,
        typer.Option(
            help="local, or ray: the grid's chunks as Ray tasks (the cluster RAY_ADDRESS names, else a local one)"
        ),
    ] = "local",
    video: Annotated[Optional[Path], typer.Option(help="write an mp4 video of each episode to this folder")] = None,
    config: Annotated[
        Optional[Path], typer.Option(help="TOML config (scenario/sim settings), as orbitdata fly")
    ] = None,
) -> None:
    """Fly a planning pilot (or a policy run) over the orbitdata fly grid and print the success table.

    Seeds are orbitdata fly's, so `orbitdata fly --pilot expert --json E.json` flies the same
    episodes; `orbitmodel eval figure6 E.json P.json ... --out fig6.png` plots them together.
    `--batch 8` flies 8 episodes at a time, one model call for all of them per control step
    (docs/planner.md); `--executor ray` spreads the grid over a Ray cluster, the same episodes.
    """
    import torch

    from orbitdata.cli.options import check_report_path, check_video_folder, key_values
    from orbitdata.config import GenerationConfig
    from orbitmodel.evaluate.closed_loop import ClosedLoop, ClosedLoopRequest, pilot_settings
    from orbitmodel.model.world_model import bfloat16_is_native

    options = key_values(set_ or [], "--set", "samples=32")
    settings, preset = pilot_settings(run, preset, **options)
    if getattr(settings, "precision", "float32") == "bfloat16" and not bfloat16_is_native():
        typer.echo(
            "note: this CPU has neither AVX-512 BF16 nor AMX, so precision=bfloat16 is emulated: "
            "it can be slower than float32 here",
            err=True,
        )
    torch.set_num_threads(threads)
    req = ClosedLoopRequest(
        variant=Variant(pilot.value),
        run=run,
        obstacles=tuple(_numbers(obstacles, int, "--obstacles")),
        speeds=tuple(_numbers(speeds, float, "--speeds")),
        episodes=episodes,
        seed=seed,
        settings=settings,
        preset=preset,
        config=GenerationConfig.from_toml(config) if config else GenerationConfig(),
        max_steps=max_steps,
        video_dir=video,
        batch=batch,
        executor=executor.value,
    )
    check_report_path(json_out)
    check_video_folder(video)
    with _flying(json_out):
        loop = ClosedLoop(req)  # everything that can be refused is refused here, before the progress bar
        log, kept = _chunk_log(loop, json_out)
        report = loop.report(_fly_with_progress(loop, json_out, log, kept))
        print_table(report, episodes)
        if json_out is not None:
            json_out.write_text(json.dumps(report, indent=2) + "\n")
            log.remove()


def _flying(json_out: Path | None):
    """With ``--json``, hold its table's lock (``kept_chunks.flight_lock``) for the flight: a second
    flight to the same table is refused."""
    if json_out is None:
        return contextlib.nullcontext()
    from orbitmodel.evaluate.kept_chunks import flight_lock

    return flight_lock(json_out)


def _chunk_log(loop, json_out: Path | None):
    """With ``--json``, the flight's kept chunks (``evaluate.kept_chunks``): those a cut flight of
    this same command left are read, and said so; a file left by another flight is replaced once
    this flight's first chunk lands."""
    if json_out is None:
        return None, {}
    from orbitmodel.evaluate.kept_chunks import ChunkLog, chunk_log_path

    log = ChunkLog(chunk_log_path(json_out), loop.key())
    kept = log.resume(loop.parts())
    if kept:
        flown = sum(len(chunk.episodes) for chunk in kept.values())
        typer.echo(f"resuming: {flown} of {len(loop.order)} episodes were flown by a cut flight ({log.path})", err=True)
    elif log.replaced:
        typer.echo(
            f"note: {log.path} was left by another flight (other flags, weights or code): flying afresh, "
            "it is replaced when this flight's first chunk lands",
            err=True,
        )
    return log, kept


def _fly_with_progress(loop, json_out: Path | None, log=None, kept=None):
    """Fly ``loop`` under a progress bar; with ``--json``, stream each episode to
    ``*.episodes.jsonl`` as it lands, so a grid stopped early keeps what it flew, and keep each
    finished chunk in ``log`` (``kept_chunks.ChunkLog``), so that the same command run again
    continues from it."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    stream = None
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        stream = json_out.with_suffix(".episodes.jsonl").open("w")
    req = loop.req
    with Progress(
        TextColumn(f"[bold]fly {loop.name}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
    ) as bar:
        task = bar.add_task("fly", total=len(req.obstacles) * len(req.speeds) * req.episodes)

        def landed(cell, record: dict) -> None:
            bar.advance(task)
            if stream is not None:
                stream.write(json.dumps(record) + "\n")
                stream.flush()

        try:
            return loop.fly(on_episode=landed, kept=kept, on_chunk=log.add if log else None)
        except (ValueError, ArithmeticError) as exc:
            # every refusal of the request came before the bar: a failure now is the flight's, not bad input
            where = f"; those are in {stream.name}" if stream is not None else ""
            flown = int(bar.tasks[0].completed)
            fail(
                f"the flight stopped after {flown} episode{'' if flown == 1 else 's'}: {first_line(exc)}{where}", code=1
            )
        finally:
            if stream is not None:
                stream.close()
            if log is not None:
                log.close()


def print_table(report: dict, episodes: int) -> None:
    """``orbitdata fly``'s table with each setting's 95 % Wilson interval, then the total and the
    planning latency."""
    from rich.console import Console
    from rich.table import Table

    from orbitdata.schema import outcomes
    from orbitmodel.evaluate.success import rate_text, report_totals, wilson

    table = Table(title=f"{report['pilot']} pilot, {episodes} episodes per setting, seed {report['seed']}")
    kinds = outcomes(report.get("tier", "static"))  # the dynamic tier's also count tumbling
    for col in ("obstacles", "v0 m/s", *(k.replace("_", " ") for k in kinds), "success % [95 % CI]"):
        table.add_column(col, justify="right")
    for c in report["settings"]:
        low, high = wilson(c["success"], c["episodes"])
        table.add_row(
            str(c["obstacles"]),
            f"{c['speed']:g}",
            *(str(c[k]) for k in kinds),
            f"{100 * c['success'] / c['episodes']:.0f} [{100 * low:.0f}, {100 * high:.0f}]",
        )
    console = Console()
    console.print(table)
    line = f"success {rate_text(*report_totals(report))}"
    step, replan = report["latency_ms"]["step"], report["latency_ms"]["replan"]
    if step["median"] is not None:
        line += f"; planning per control step {step['median']:.1f} ms median, {step['p95']:.1f} ms p95" + (
            f" (per replan {replan['median']:.1f} / {replan['p95']:.1f} ms)" if replan["median"] is not None else ""
        )
        if report.get("batch", 1) > 1:
            line += f", each step for up to {report['batch']} episodes in lockstep"
    if report["time_share"]:
        line += "; time: " + ", ".join(f"{k} {100 * v:.0f} %" for k, v in report["time_share"].items())
    console.print(line)


def not_an_input(json_out: Path | None, inputs: list[Path]) -> None:
    """Refuse a ``--json`` that could not be written (``check_report_path``) or would overwrite one
    of the command's own inputs."""
    from orbitdata.cli.options import check_report_path

    if json_out is None:
        return
    check_report_path(json_out)
    if any(json_out.resolve() == Path(p).resolve() for p in inputs):
        fail(f"--json {json_out} is one of the inputs: give another file to write")


@friendly
def figure6(
    results: Annotated[list[Path], typer.Argument(help="JSON tables of orbitmodel eval closed-loop / orbitdata fly")],
    out: Annotated[Path, typer.Option("--out", help="PNG to write")] = Path("figure6.png"),
    title: Annotated[Optional[str], typer.Option(help="figure title")] = None,
) -> None:
    """Plot the paper's Figure 6: success per setting and on average, one bar per pilot."""
    from orbitdata.cli.options import check_report_path
    from orbitmodel.evaluate.figure6 import plot_figure6, read_report

    try:
        from matplotlib.backend_bases import FigureCanvasBase

        kinds = FigureCanvasBase.get_supported_filetypes()
    except ImportError:  # plot_figure6 says how to install it
        kinds = None
    if kinds is not None and out.suffix and out.suffix.lower().lstrip(".") not in kinds:
        fail(f"--out {out}: give a file matplotlib writes ({', '.join('.' + k for k in sorted(kinds))})")
    out = out if out.suffix else out.with_suffix(".png")  # what matplotlib writes for a bare name
    check_report_path(out, "--out")
    path = plot_figure6([read_report(p) for p in results], out, title)
    typer.echo(f"wrote {path}")


@friendly
def merge(
    parts: Annotated[list[Path], typer.Argument(help="JSON tables of one grid flown in parts (disjoint settings)")],
    json_out: Annotated[Path, typer.Option("--json", help="write the merged table here")],
) -> None:
    """Merge a grid flown in parallel (say `--speeds 1` and `--speeds 2` in two processes) into one table."""
    from orbitmodel.evaluate.closed_loop import merge_reports
    from orbitmodel.evaluate.figure6 import read_report

    not_an_input(json_out, parts)
    reports = [read_report(path) for path in parts]
    for path, report in zip(parts, reports):
        if report.get("partial"):
            fail(f"{path} is a stopped grid's episode stream: merge the --json tables of finished parts")
    try:
        report = merge_reports(reports)
    except (KeyError, TypeError) as err:
        fail(f"{parts[0]} and the others are not eval closed-loop --json tables ({type(err).__name__} {err})")
    json_out.parent.mkdir(parents=True, exist_ok=True)
    json_out.write_text(json.dumps(report, indent=2) + "\n")
    print_table(report, max(s["episodes"] for s in report["settings"]))


@friendly
def table(
    results: Annotated[list[Path], typer.Argument(help="JSON tables of orbitmodel eval closed-loop / orbitdata fly")],
    per_setting: Annotated[
        bool, typer.Option("--per-setting-ci", help="each setting's rate with its interval, not its count")
    ] = False,
    links: Annotated[bool, typer.Option(help="a last column linking each row's JSON file")] = True,
) -> None:
    """Print one grid's results as a markdown table: successes per setting, the success rate over
    all settings with its 95 % Wilson interval and episode count, and the failures."""
    from orbitmodel.evaluate.figure6 import read_report
    from orbitmodel.evaluate.success import markdown_table

    reports = [read_report(p) for p in results]
    typer.echo(markdown_table(reports, [str(p) for p in results] if links else None, per_setting), nl=False)


@friendly
def pool(
    results: Annotated[list[Path], typer.Argument(help="one pilot's grid results, one per root seed (--seed)")],
    json_out: Annotated[Optional[Path], typer.Option("--json", help="write the pooled table here")] = None,
) -> None:
    """Pool one pilot's grid over several seeds (say the test seeds 3, 4 and 5) into one table: the
    success rate over every episode with its 95 % Wilson interval, and the worst setting on any seed."""
    from orbitmodel.evaluate.figure6 import read_report
    from orbitmodel.evaluate.success import pool_seeds, rate_text, report_totals

    not_an_input(json_out, results)
    pooled = pool_seeds([read_report(p) for p in results])
    worst = pooled["worst_setting"]
    typer.echo(
        f"{pooled['pilot']}, seeds {', '.join(map(str, pooled['seeds']))}: {rate_text(*report_totals(pooled))}; "
        f"worst setting: seed {worst['seed']}, {worst['obstacles']} obstacles at {worst['speed']:g} m/s, "
        f"{worst['success']}/{worst['episodes']}"
    )
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(pooled, indent=2) + "\n")


@friendly
def factors(
    results: Annotated[
        list[Path], typer.Argument(help="grid results with their episodes: eval closed-loop, orbitdata fly, eval pool")
    ],
    json_out: Annotated[Optional[Path], typer.Option("--json", help="write the breakdowns here")] = None,
) -> None:
    """Print each grid's success by what its episodes were dealt (debris moving or still, a faulty
    thruster and its kind, eclipse, the CW terms), each with its 95 % Wilson interval, and how they
    flew: failures by kind, the closest approach, and the delta-v and time to the goal of a success.
    One row per file, named by the file (with its folders, where two files share a name)."""
    from orbitmodel.evaluate.factors import breakdown, distinct_names, factor_tables
    from orbitmodel.evaluate.figure6 import read_report

    not_an_input(json_out, results)
    rows = []
    for name, path in zip(distinct_names(results), results):
        try:
            rows.append((name, breakdown(read_report(path))))
        except ValueError as err:
            fail(str(err) if str(err).startswith(str(path)) else f"{path}: {err}")
        except KeyError as err:  # a record older code wrote, or one edited by hand
            fail(f"{path}: an episode has no {err} record; give a grid that eval closed-loop or orbitdata fly wrote")
    typer.echo(factor_tables(rows), nl=False)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps({name: b for name, b in rows}, indent=2) + "\n")


@friendly
def flips(
    first: Annotated[Path, typer.Argument(help="a grid's --json table (eval closed-loop)")],
    second: Annotated[Path, typer.Argument(help="the same grid flown again with a tiny perturbation")],
    json_out: Annotated[Optional[Path], typer.Option("--json", help="write the comparison here")] = None,
) -> None:
    """Count the episodes whose outcome differs between two flights of one grid (e.g. --threads 1
    and 2, or two machines): a planner whose figures hold flips few."""
    from orbitmodel.evaluate.figure6 import read_report
    from orbitmodel.evaluate.success import outcome_flips

    not_an_input(json_out, [first, second])
    result = {"flights": [str(first), str(second)]}  # the JSON names what it compares
    result |= outcome_flips(read_report(first), read_report(second), (str(first), str(second)))
    typer.echo(
        f"{result['flips']} of {result['episodes']} episodes flip (successes {result['successes'][0]} vs "
        f"{result['successes'][1]})"
    )
    if "only_first" in result or "only_second" in result:
        typer.echo(
            f"compared the {result['episodes']} episodes both flew: {result.get('only_first', 0)} more in {first}, "
            f"{result.get('only_second', 0)} more in {second}"
        )
    if "identical" in result:
        c, f = result["clearance_change_m"], result["frames_change"]
        typer.echo(
            f"{result['identical']} of {result['episodes']} flown identically; closest approach changed by "
            f"{c['median']:.3f} m median ({c['max']:.3f} max), frames by {f['median']:g} median ({f['max']} max)"
        )
    for f in result["flipped"]:
        typer.echo(
            f"  {f['obstacles']} obstacles, {f['speed']:g} m/s, episode {f['episode']}: {f['first']} -> {f['second']}"
        )
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(result, indent=2) + "\n")
