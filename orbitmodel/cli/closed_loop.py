"""``orbitmodel eval closed-loop`` and ``orbitmodel eval figure6``: the planner on the fly grid."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from orbitmodel.cli.errors import fail, friendly
from orbitmodel.plan.pilot import Variant

PilotName = Enum("PilotName", {v.value: v.value for v in Variant}, type=str)
DepthHead = Enum("DepthHead", {"auto": "auto", "stage1": "stage1", "refit": "refit"}, type=str)
VideoFormat = Enum("VideoFormat", {"mp4": "mp4", "gif": "gif"}, type=str)


def register(app: typer.Typer) -> None:
    app.command("closed-loop")(closed_loop)
    app.command("figure6")(figure6)
    app.command("merge")(merge)


def _numbers(text: str, kind, flag: str) -> list:
    try:
        values = [kind(x) for x in text.split(",") if x.strip()]
    except ValueError:
        values = None
    if not values:
        fail(f"{flag} {text!r} must be a comma-separated list of numbers, e.g. {flag} 1,3,5")
    return values


@friendly
def closed_loop(
    run: Annotated[Optional[Path], typer.Argument(help="Stage I run folder (with its probe); optional for the "
                                                        "rigid-body oracles")] = None,
    pilot: Annotated[PilotName, typer.Option(help="planner, or an oracle (true dynamics and/or obstacles)")] = "planner",
    obstacles: Annotated[str, typer.Option(help="obstacle counts, comma-separated")] = "1,3,5",
    speeds: Annotated[str, typer.Option(help="initial speeds in m/s, comma-separated")] = "1,2",
    episodes: Annotated[int, typer.Option(help="episodes per setting")] = 20,
    seed: Annotated[int, typer.Option(min=0, help="root seed of the grid (as orbitdata fly)")] = 0,
    json_out: Annotated[Optional[Path], typer.Option("--json", help="write the table and every episode here")] = None,
    video: Annotated[Optional[Path], typer.Option(help="write a video of each episode to this folder")] = None,
    video_format: Annotated[VideoFormat, typer.Option(help="mp4 or gif")] = "mp4",
    samples: Annotated[Optional[int], typer.Option(min=2, help="MPPI samples K [default: 256]")] = None,
    horizon: Annotated[Optional[int], typer.Option(
        min=1, help="MPPI horizon H in control steps (frames), a multiple of the run's --frame-step [default: 50]")
    ] = None,
    iterations: Annotated[Optional[int], typer.Option(min=1, help="MPPI iterations per replan [default: 1]")] = None,
    replan_every: Annotated[Optional[int], typer.Option(min=1, help="control steps per replan [default: 1]")] = None,
    memory_frames: Annotated[Optional[int], typer.Option(min=1, help="depth frames kept in the point cloud")] = None,
    support: Annotated[Optional[int], typer.Option(
        min=0, max=8, help="keep a depth cell only with this many of its 8 neighbours at a similar depth (0: off) "
                           "[default: 1]")] = None,
    depth_head: Annotated[DepthHead, typer.Option(help="stage1: the head trained with the world model; refit: "
                                                       "RUN/depth (`orbitmodel depth`); auto: refit if there")] = "auto",
    history: Annotated[Optional[int], typer.Option(min=1, help="latents the world model sees per imagined step "
                                                               "[default: the model's own, 8]")] = None,
    max_steps: Annotated[Optional[int], typer.Option(min=2, help="frames per episode at most [default: 300]")] = None,
    threads: Annotated[int, typer.Option(min=1, help="torch threads (1 is fastest for these small batches)")] = 1,
    compile_rollout: Annotated[bool, typer.Option("--compile", help="torch.compile the world model's imagined step "
                                                                   "(needs a C++ compiler; ~35 % faster rollouts)")] = False,
    config: Annotated[Optional[Path], typer.Option(help="TOML config (scenario/sim settings), as orbitdata fly")] = None,
) -> None:
    """Fly a planning pilot over the orbitdata fly grid and print the success table.

    Seeds are orbitdata fly's, so `orbitdata fly --pilot expert --json E.json` flies the same
    episodes; `orbitmodel eval figure6 E.json P.json ... --out fig6.png` plots them together.
    """
    import torch
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from orbitdata.config import GenerationConfig
    from orbitmodel.evaluate.closed_loop import ClosedLoop, ClosedLoopRequest, closed_loop_report
    from orbitmodel.plan.factory import planner_config

    n_obst, v = _numbers(obstacles, int, "--obstacles"), _numbers(speeds, float, "--speeds")
    options = {k: x for k, x in dict(samples=samples, horizon=horizon, iterations=iterations,
                                     replan_every=replan_every, memory_frames=memory_frames,
                                     history=history, support=support).items() if x is not None}
    options["depth_head"] = depth_head.value
    options["compile"] = compile_rollout
    torch.set_num_threads(threads)
    req = ClosedLoopRequest(variant=Variant(pilot.value), run=run, obstacles=tuple(n_obst), speeds=tuple(v),
                            episodes=episodes, seed=seed, planner=planner_config(**options),
                            config=GenerationConfig.from_toml(config) if config else GenerationConfig(),
                            max_steps=max_steps, video_dir=video, video_format=f".{video_format.value}")
    loop = ClosedLoop(req)  # everything that can be refused is refused here, before the progress bar
    console = Console(stderr=True)
    stream = None
    if json_out is not None:  # each episode as it lands, so a grid stopped early keeps what it flew
        json_out.parent.mkdir(parents=True, exist_ok=True)
        stream = json_out.with_suffix(".episodes.jsonl").open("w")

    def landed(cell, record: dict) -> None:
        bar.advance(task)
        if stream is not None:
            stream.write(json.dumps(record) + "\n")
            stream.flush()

    with Progress(TextColumn(f"[bold]fly {pilot.value}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  console=console) as bar:
        task = bar.add_task("fly", total=len(n_obst) * len(v) * episodes)
        try:
            result = loop.fly(on_episode=landed)
        finally:
            if stream is not None:
                stream.close()
    report = closed_loop_report(req, result)
    print_table(report, episodes)
    if json_out is not None:
        json_out.write_text(json.dumps(report, indent=2) + "\n")


def print_table(report: dict, episodes: int) -> None:
    """``orbitdata fly``'s table, then the average and the planning latency."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{report['pilot']} pilot, {episodes} episodes per setting, seed {report['seed']}")
    for col in ("obstacles", "v0 m/s", "success", "collision", "timeout", "out of fuel", "success %"):
        table.add_column(col, justify="right")
    rates = []
    for c in report["settings"]:
        rate = c["success"] / c["episodes"]
        rates.append(rate)
        table.add_row(str(c["obstacles"]), f"{c['speed']:g}", str(c["success"]), str(c["collision"]),
                      str(c["timeout"]), str(c["out_of_fuel"]), f"{100 * rate:.0f}")
    console = Console()
    console.print(table)
    step, replan = report["latency_ms"]["step"], report["latency_ms"]["replan"]
    shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in report["time_share"].items())
    console.print(f"average success {100 * sum(rates) / len(rates):.1f} %; planning per control step "
                  f"{step['median']:.1f} ms median, {step['p95']:.1f} ms p95 (per replan {replan['median']:.1f} / "
                  f"{replan['p95']:.1f} ms); time: {shares}")


@friendly
def figure6(
    results: Annotated[list[Path], typer.Argument(help="JSON tables of orbitmodel eval closed-loop / orbitdata fly")],
    out: Annotated[Path, typer.Option("--out", help="PNG to write")] = Path("figure6.png"),
    title: Annotated[Optional[str], typer.Option(help="figure title")] = None,
) -> None:
    """Plot the paper's Figure 6: success per setting and on average, one bar per pilot."""
    from orbitmodel.evaluate.figure6 import plot_figure6, read_report

    path = plot_figure6([read_report(p) for p in results], out, title)
    typer.echo(f"wrote {path}")


@friendly
def merge(
    parts: Annotated[list[Path], typer.Argument(help="JSON tables of one grid flown in parts (disjoint settings)")],
    json_out: Annotated[Path, typer.Option("--json", help="write the merged table here")],
) -> None:
    """Merge a grid flown in parallel, e.g. `--speeds 1` and `--speeds 2` in two processes, into one table."""
    from orbitmodel.evaluate.closed_loop import merge_reports

    reports = []
    for path in parts:
        try:
            reports.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError) as err:
            fail(f"{path}: not a readable grid result ({err}); give the --json tables of eval closed-loop")
    try:
        report = merge_reports(reports)
    except (KeyError, TypeError) as err:
        fail(f"{parts[0]} and the others are not eval closed-loop --json tables ({type(err).__name__} {err})")
    json_out.parent.mkdir(parents=True, exist_ok=True)
    json_out.write_text(json.dumps(report, indent=2) + "\n")
    print_table(report, max(s["episodes"] for s in report["settings"]))
