"""What a run publishes, and whether it is complete enough to publish.

A Stage I run goes up with its sub-runs (the physics probe, the state-only reference, the
refitted depth head), its evaluations (``RUN/eval``: ``rollout.json``, ``probe_table.json`` and
their figures; grid results in ``RUN/eval/grid/``) and its training record; a policy run with
its own. Checkpoints, TensorBoard events and the probe's latent cache stay home: they are for
resuming, not for using.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

from orbitmodel.plan.depth_recipe import head_folder, head_name
from orbitmodel.runs import (
    CHECKPOINTS,
    CONFIG,
    MAKES,
    METRICS,
    POLICY,
    TRAINING,
    WEIGHTS,
    WORLD_MODEL,
    RunError,
    stage_of,
)

# a Stage I run's sub-run folders: the probes, the refitted and the imagined depth heads, the
# inferred body's prior (orbitmodel body)
SUB_RUNS = ("probe", "probe-state", "depth", "depth-imagined", "body")
SUB_RUN_FILES = (CONFIG, WEIGHTS, METRICS, TRAINING, "eval.json")
EVAL = "eval"
GRID = "eval/grid"  # grid results (eval closed-loop / orbitdata fly --json) shown on the card
EVAL_SUFFIXES = (".json", ".md", ".png")


@dataclass(frozen=True)
class RunFile:
    rel: str  # path in the repo
    path: Path  # the local file
    bytes: int


def check_complete(run: Path) -> str:
    """The run's stage, or RunError naming what is missing and the command that makes it: final
    weights (not just checkpoints), and for a Stage I run a probe trained on these weights."""
    run = Path(run)
    if not (run / CONFIG).is_file():
        raise RunError(
            f"{run} is not an orbitmodel run (no {CONFIG}); push a folder made by `orbitmodel train` "
            "or `orbitmodel train-policy`"
        )
    stage = stage_of(run)
    if stage not in (WORLD_MODEL, POLICY):
        raise RunError(f"{run} holds a {stage!r} sub-run; push the run folder above it")
    if not (run / WEIGHTS).is_file():
        state = (
            "has only checkpoints: its training has not finished" if (run / CHECKPOINTS).is_dir() else "has no weights"
        )
        raise RunError(f"{run} {state}; finish it (`{MAKES[stage]} --resume`) before pushing")
    if stage == WORLD_MODEL:
        from orbitmodel.model.world_model import WorldModel
        from orbitmodel.plan.depth_refit import load_refit_head
        from orbitmodel.probe.model import load_probe

        model = WorldModel.from_pretrained(run)
        try:
            load_probe(run, "latent", model.fingerprint)
            if (run / head_folder() / WEIGHTS).is_file():  # a refit the planner would refuse must not go up either
                load_refit_head(run, model)
            for sub in named_heads(run):
                load_refit_head(run, model, head_name(sub))
        except RunError as err:
            raise RunError(f"incomplete run, not pushed: {err}") from None
    return stage


def named_heads(run: Path) -> tuple[str, ...]:
    """The run's depth heads refitted under a name (``orbitmodel depth --name``): RUN/depth-NAME."""
    return tuple(sorted(p.name for p in Path(run).glob(f"{head_folder()}-*") if p.is_dir() and head_name(p.name)))


def is_grid_result(path: Path) -> bool:
    """A ``--json`` table of eval closed-loop / orbitdata fly (pilot and settings)."""
    try:
        report = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(report, dict) and "pilot" in report and isinstance(report.get("settings"), list)


def run_files(run: Path, grids: tuple[Path, ...] = ()) -> list[RunFile]:
    """Every file a push of ``run`` uploads (the card aside), in upload order; ``grids``: folders
    of grid results (their own JSON tables, not their sub-folders') to publish under
    eval/grid/FOLDER/ as well."""
    run = Path(run)
    found: dict[str, Path] = {}
    for name in (CONFIG, WEIGHTS, METRICS, TRAINING):
        if (run / name).is_file():
            found[name] = run / name
    for sub in SUB_RUNS + named_heads(run):
        for name in SUB_RUN_FILES:
            if (run / sub / name).is_file():
                found[f"{sub}/{name}"] = run / sub / name
    if (run / EVAL).is_dir():
        for path in sorted((run / EVAL).rglob("*")):
            if path.is_file() and path.suffix in EVAL_SUFFIXES and not path.name.endswith(".episodes.jsonl"):
                found[path.relative_to(run).as_posix()] = path
    for grid in map(Path, grids):
        results = sorted(p for p in grid.glob("*.json") if is_grid_result(p)) if grid.is_dir() else []
        if not results:
            raise RunError(
                f"--grid {grid}: no grid results there (the --json tables of eval closed-loop / orbitdata "
                "fly); give the folder that holds them"
            )
        for path in results:
            found[f"{GRID}/{grid.resolve().name}/{path.name}"] = path
    weights_last = sorted(found, key=lambda rel: (rel.endswith(WEIGHTS), rel))  # configs and evals first
    return [RunFile(rel, found[rel], found[rel].stat().st_size) for rel in weights_last]


def read_json(files: list[RunFile], rel: str) -> dict | None:
    """The JSON file published at ``rel``, if the push holds it."""
    match = next((f for f in files if f.rel == rel), None)
    return None if match is None else json.loads(match.path.read_text())


ABSOLUTE = re.compile(r"(?<![\w:/.])/(?:[\w.+-]+/)+([\w.+-]+)")  # a POSIX absolute path in text: keep its last part


def scrub_paths(value):
    """``value`` (JSON data or text) with every absolute local path cut to its last part, so that a
    push publishes no home folder or machine layout (``/home/me/runs/wm`` -> ``wm``)."""
    if isinstance(value, dict):
        return {k: scrub_paths(v) for k, v in value.items()}
    if isinstance(value, list):
        return [scrub_paths(v) for v in value]
    if isinstance(value, str):
        return ABSOLUTE.sub(lambda m: m.group(1), value)
    return value


def published_bytes(f: RunFile) -> bytes:
    """What goes up for ``f``: text files (JSON, markdown) with local paths scrubbed, the rest as is."""
    if f.path.suffix == ".json":
        return (json.dumps(scrub_paths(json.loads(f.path.read_text())), indent=2, sort_keys=True) + "\n").encode()
    if f.path.suffix in (".md", ".jsonl"):
        return scrub_paths(f.path.read_text()).encode()
    return f.path.read_bytes()
