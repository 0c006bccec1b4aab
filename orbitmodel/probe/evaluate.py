"""The paper's Table I and Figure 5 (``orbitmodel eval probe RUN DATASET``).

Two tables from the same windows: ``table1.json`` (``probe.table1``: the paper's probe and the
rows to read it against, at the planner's history and the model's) and ``probe_table.json``, the
run's probe with the state-only MLP and constant velocity at one history (the model card's).

Protocol (upstream's eval_stage2, at the paper's horizons): test-split episodes in a seeded
random order, one random window per episode whose frames hold no collision, until ``windows``
windows; ``context`` frames are encoded, the world model imagines the next ``max(horizons)``
latents from the logged actions, and the probe integrates them from the true state at the last
context frame. Per window, the error is averaged over steps 1..h (per quantity: the mean absolute
error over its components; the attitude as the geodesic angle); the table gives its mean +- std
over the windows. The state-only MLP and constant velocity run on the same windows. The rollouts
of the two horizons are one rollout (a prediction does not depend on what comes after it).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from orbitdata import schema as S
from orbitdata.load import collate_windows, load_windows
from orbitdata.load.index import NoWindow
from orbitmodel.data import group_actions, read_dataset_meta, split_selection
from orbitmodel.probe import table1
from orbitmodel.probe.baselines import StateDynamics, constant_velocity
from orbitmodel.probe.metrics import PAPER, QUANTITIES, step_errors, summarise
from orbitmodel.probe.model import PhysicsProbe, probe_folder
from orbitmodel.probe.train import load_stage1
from orbitmodel.runs import CONFIG, RunError, local_run_folder
from orbitmodel.train.loop import resolve_device

ROWS = {
    "probe": "ours: probe on imagined latents",
    "state_mlp": "state-only MLP (state, action)",
    "constant_velocity": "constant velocity (coasting)",
}
TABLE_JSON, TABLE_MD = "probe_table.json", "probe_table.md"
BATCH = 25  # windows per forward pass


@dataclass(frozen=True)
class EvalRequest:
    run: Path
    dataset: str
    windows: int = 100
    seed: int = 0
    horizons: tuple[int, ...] = (25, 50)
    out: Path | None = None  # default RUN/eval
    device: str = "cpu"
    figures: bool = True
    history: int | None = None  # latents the world model sees per imagined step (None: its own, config.history)
    split: str = "test"  # or "val": the run's validation episodes (choices are made there; test only reports)
    context: int | None = None  # model steps encoded before the horizon (None: the probe's training context)


def select_windows(dataset: str, context: int, horizon: int, count: int, seed: int, split: str = "test", episodes=None):
    """(collision-free window indices, a window ending on a collision or None) into the windows of
    ``context + horizon`` frames (stride 1) of ``split`` (``episodes`` of it); one window per
    episode, seeded."""
    flags = load_windows(
        dataset, split=split, context=context, horizon=horizon, stride=1, columns=[S.COLLISION], episodes=episodes
    )
    episode = flags.index.episode  # (N,) episode_index of each window
    rng = np.random.default_rng(seed)
    chosen, collided = [], []
    for e in rng.permutation(np.unique(episode)):
        candidates = np.flatnonzero(episode == e)  # in frame order
        if flags[int(candidates[-1])][S.COLLISION].any():
            collided.append(int(candidates[-1]))  # the window that ends on the collision
        if len(chosen) < count:
            for c in rng.permutation(candidates):
                if not flags[int(c)][S.COLLISION].any():
                    chosen.append(int(c))
                    break
    if len(chosen) < count:
        which = f"{split} episodes" if episodes is None else f"held-out validation episodes ({split} split)"
        raise RunError(
            f"only {len(chosen)} {which} of {dataset} hold a collision-free window of "
            f"{context} + {horizon} frames; ask for --windows {len(chosen)} or fewer, or shorter horizons"
        )
    return chosen, (collided[0] if collided else None)


@torch.no_grad()
def predict(
    world_model, probe, state_mlp, batch: dict, context: int, n: int, device, history: int | None = None
) -> dict[str, torch.Tensor]:
    """Every row's states (K, n, 16) for windows (K, context + n, ...) of frames, and the truth.

    A world model with ``frame_step`` s > 1 encodes every s-th context frame (``context`` = its
    (m - 1) s + 1 frames) and imagines n / s steps; its probe gives every frame's state as the
    planner reads it (:meth:`PhysicsProbe.per_frame`: predicted per frame, or interpolated)."""
    m, s = context, world_model.config.frame_step
    images, states, actions = (batch[k].to(device) for k in (S.IMAGE, S.STATE, S.ACTION))
    z = world_model.encode(images[:, :m:s], states[:, :m:s])  # (K, context steps, D)
    steps = group_actions(actions[:, : m - 1 + n], s)  # (K, context steps - 1 + n / s, 8 s): taken, then imagined
    z_future = world_model.rollout(z, steps, history)  # (K, n / s, D)
    out = {
        "truth": states[:, m : m + n].float(),
        "probe": probe.per_frame(z_future, states[:, m - 1], z[:, -1], s, steps[:, -(n // s) :]),  # (K, n, 16)
        "constant_velocity": constant_velocity(states[:, m - 1], n, S.DT),
    }
    if state_mlp is not None:
        out["state_mlp"] = state_mlp(states[:, m - 1], actions[:, m - 1 : m - 1 + n])
    return {k: v.cpu() for k, v in out.items()}


def _cell(row: dict | None, q: str, h: int) -> str:
    if row is None:
        return "not trained"
    e = row[q][f"h{h}"]
    return f"{e['mean']:.4f} ± {e['std']:.4f}"


def markdown(result: dict) -> str:
    """The table: ours beside the paper and the reference rows, one line per quantity and horizon."""
    t = result["table"]
    lines = [
        f"Physics probe, {result['windows']} collision-free {result.get('split', 'test')} windows (seed "
        f"{result['seed']}), "
        f"context {result['context']}"
        + (f", the world model seeing {result['history']} latents per imagined step" if "history" in result else "")
        + ", MAE ± std over windows, averaged over steps 1..h (dt = 0.04 s)"
        + (
            f"; the world model steps {result['frame_step']} frames at a time and its probe's states are "
            + ("predicted for every frame" if result.get("per_frame") else "interpolated to every frame")
            + ", as the planner reads them."
            if result.get("frame_step", 1) > 1
            else "."
        ),
        f"World model: `{result['run']}` (preset {result['preset']}); dataset `{result['dataset']}`; "
        f"probe inputs: {result['probe_inputs']}; "
        f"integrator: {', '.join(f'{k} {v}' for k, v in result['integrators'].items())}.",
        "",
        "| quantity | h | ours | paper | state-only MLP | constant velocity |",
        "|---|---|---|---|---|---|",
    ]
    for q, unit in QUANTITIES.items():
        for h in result["horizons"]:
            paper = PAPER.get(h, {}).get(q)
            lines.append(
                f"| {q.replace('_', ' ')} ({unit}) | {h} | {_cell(t['probe'], q, h)} | "
                f"{'-' if paper is None else f'{paper:.4f}'} | {_cell(t.get('state_mlp'), q, h)} | "
                f"{_cell(t['constant_velocity'], q, h)} |"
            )
    if t.get("state_mlp") is None and result.get("frame_step", 1) > 1:
        lines += ["", "No state-only row: that reference is per frame and is not trained for a frame-step run."]
    elif t.get("state_mlp") is None:
        lines += ["", f"The state-only row needs `orbitmodel probe {result['run']} DATASET --state-only` first."]
    return "\n".join(lines) + "\n"


def evaluate_probe(req: EvalRequest, physics: table1.Physics | None = None) -> dict:
    """Table I (``table1.json``/``.md``: every row, at the planner's history and the model's), the
    run's probe table (``probe_table.json``/``.md``, at ``req.history``) and Figure 5 (PNGs);
    returns the probe table's result dict with Table I's under "table1". ``physics``: the
    rigid-body model for Table I's physics row (``orbitmodel.plan``'s, passed in by the CLI)."""
    if req.windows < 1 or not req.horizons or min(req.horizons) < 1:
        raise ValueError(f"windows={req.windows}, horizons={req.horizons}: give at least one window and horizons >= 1")
    if req.out is None:
        local_run_folder(req.run, "eval probe without --out")  # before the evaluation, not after
    world_model = load_stage1(req.run, read_dataset_meta(req.dataset))
    probe = PhysicsProbe.from_pretrained(world_model.run_dir, world_model=world_model.fingerprint)
    probe_config = json.loads((probe_folder(world_model.run_dir, "latent") / CONFIG).read_text())
    try:
        state_mlp = StateDynamics.from_pretrained(world_model.run_dir)
    except RunError:
        state_mlp = None  # the table says how to add it
    device = resolve_device(req.device)
    world_model, probe = world_model.to(device), probe.to(device)
    state_mlp = state_mlp.to(device) if state_mlp is not None else None
    s = world_model.config.frame_step
    if req.history is not None and not 1 <= req.history <= world_model.config.history:
        raise RunError(
            f"--history {req.history}: the world model of {req.run} rolls out from 1 to "
            f"{world_model.config.history} latents"
        )
    if any(h % s for h in req.horizons):
        raise RunError(
            f"{req.run} predicts {s} frames per step; give horizons that are multiples of {s} "
            f"(got {', '.join(map(str, req.horizons))})"
        )
    if req.context is not None and req.context < 1:
        raise ValueError(f"--context {req.context}: encode at least 1 step before the horizon")
    # the context frames: every s-th of (steps - 1) s + 1, the last one where the probe starts
    steps = req.context or int(probe_config["train"]["context"])
    context, n = (steps - 1) * s + 1, max(req.horizons)
    split, episodes = split_selection(req.split, world_model.run.validation)
    try:
        chosen, collided = select_windows(req.dataset, context, n, req.windows, req.seed, split, episodes)
    except NoWindow as err:  # in the flags, with the longest horizon that fits
        most = err.longest - context
        raise ValueError(
            f"--horizon {n}: {context} context frames and {n} horizon frames are longer than every episode of "
            f"the {req.split} split of {req.dataset} (longest: {err.longest} frames); "
            + (f"give --horizon {most} or less" if most >= 1 else "give a shorter --context")
        ) from None
    windows = load_windows(
        req.dataset,
        split=split,
        context=context,
        horizon=n,
        stride=1,
        episodes=episodes,
        columns=[S.IMAGE, S.STATE, S.ACTION],
    )
    rows = table1.load_rows(world_model.run_dir, world_model, probe, req.split, device)
    if physics is None:
        rows.missing["physics"] = "the rigid-body model is the planner's; `orbitmodel eval probe` passes it in"
    histories = table1.table_histories(world_model.config.history, req.history)
    errors: dict[str, dict[str, list]] = {}
    errors1: dict = {}  # Table I's: history -> row -> quantity -> list of (K, n)
    first, first_frames = None, []
    for i in range(0, len(chosen), BATCH):
        batch = collate_windows(windows.__getitems__(chosen[i : i + BATCH]))
        table1.add_errors(
            errors1, table1.predict_rows(world_model, rows.probes, batch, context, n, device, histories, physics)
        )
        states = predict(world_model, probe, state_mlp, batch, context, n, device, req.history)
        first = first or {"batch": batch, "states": states}
        first_frames += [int(f) for f in batch[S.FRAME_INDEX][:, 0]]
        for row in (r for r in ROWS if r in states):
            for q, e in step_errors(states[row], states["truth"]).items():
                errors.setdefault(row, {}).setdefault(q, []).append(e)
    table = summarise({r: {q: torch.cat(v) for q, v in per_q.items()} for r, per_q in errors.items()}, req.horizons)
    table.setdefault("state_mlp", None)
    history = req.history or world_model.config.history
    result = {
        "run": str(req.run),
        "dataset": str(req.dataset),
        "preset": world_model.run.preset.name,
        "windows": len(chosen),
        "split": req.split,
        "seed": req.seed,
        "context": context,
        "frame_step": s,
        "history": history,
        "horizons": list(req.horizons),
        "dt": S.DT,
        "paper": {f"h{h}": v for h, v in PAPER.items()},
        "rows": ROWS,
        "probe_inputs": probe.config.inputs,
        "per_frame": probe.config.substeps > 1,
        "integrators": {
            "probe": probe.config.integrator,
            **({"state-only": state_mlp.config.integrator} if state_mlp is not None else {}),
        },
        "episodes": [int(windows.index.episode[c]) for c in chosen],
        "first_frames": first_frames,
        "table": table,
    }
    out = Path(req.out) if req.out is not None else local_run_folder(req.run, "eval probe without --out") / "eval"
    out.mkdir(parents=True, exist_ok=True)
    (out / TABLE_JSON).write_text(json.dumps(result, indent=2) + "\n")
    (out / TABLE_MD).write_text(markdown(result))
    result["files"] = [str(out / TABLE_JSON), str(out / TABLE_MD)]
    keep = ("run", "dataset", "preset", "windows", "split", "seed", "context", "frame_step", "horizons", "dt", "paper")
    one = table1.build(rows, errors1, req.horizons, {**{k: result[k] for k in keep}, "episodes": result["episodes"]})
    one["first_frames"] = first_frames
    if rows.candidates:  # the validation split chooses the latent_probe row for the test split
        where = local_run_folder(req.run, "choosing the latent_probe")
        one["choice_file"] = str(table1.save_choice(where, one, rows, world_model.fingerprint))
    (out / table1.TABLE1_JSON).write_text(json.dumps(one, indent=2) + "\n")
    (out / table1.TABLE1_MD).write_text(table1.markdown(one))
    result["table1"] = one
    result["files"] += [str(out / table1.TABLE1_JSON), str(out / table1.TABLE1_MD)]
    if req.figures:
        from orbitmodel.probe.figures import figure5

        crash = None
        if collided is not None:
            batch = collate_windows(windows.__getitems__([collided]))
            crash = {
                "batch": batch,
                "states": predict(world_model, probe, state_mlp, batch, context, n, device, req.history),
            }
        result["files"] += figure5(first, crash, req.dataset, context, S.DT, out, split)
    return result
