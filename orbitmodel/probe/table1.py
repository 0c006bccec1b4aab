"""Table I as the paper computes it, with the rows to read it against (``orbitmodel eval probe``).

Its rows, every one started from the true state at the last context frame of the same windows:

* ``paper_probe``: the paper's probe, imagined latents only, upstream's integrator (``RUN/probe-paper_probe``);
* ``latent_probe``: our best probe that reads no thrusts, chosen on the run's validation episodes
  among the trained ``latent_probe-*`` candidates (``RUN/probe-latent_probe-*``; the choice is
  ``RUN/latent_probe.json``, written by ``eval probe --split val``);
* ``thrust_probe``: the run's probe (``RUN/probe``), the planner's; the flown one reads each
  imagined step's thrusts beside the latents, so it is a planner component, not the paper's probe;
* ``thrust_only``: that probe retrained with no latent input (``RUN/probe-thrust_only``);
* ``physics``: the rigid-body model the simulator integrates, fed the logged thrusts;
* ``constant_velocity``: coasting: the world-frame velocity, the body rates and the fuel held.

The rows that read latents are given at each history (latents the world model sees per imagined
step): the planner's 2 and the model's own. A row whose probe is not trained is left out, with a
note naming the command that trains it. The physics row needs the planner's rigid-body model,
a layer above this package: the CLI passes it in (``physics``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch

from orbitdata import schema as S
from orbitmodel.data import group_actions
from orbitmodel.probe.baselines import constant_velocity
from orbitmodel.probe.metrics import PAPER, QUANTITIES, step_errors, summarise
from orbitmodel.probe.model import PhysicsProbe, probe_folder
from orbitmodel.probe.variants import CANDIDATES, FLOWN, LATENT, THRUST_ONLY, folder_name, train_command
from orbitmodel.probe.variants import PAPER as PAPER_PROBE
from orbitmodel.runs import CONFIG, RunError, fingerprint, write_json_atomic

ROWS = {
    PAPER_PROBE: "the paper's probe: imagined latents only, increments integrated by upstream's integrator",
    LATENT: "our probe reading imagined latents only (no thrusts), chosen on the validation episodes",
    FLOWN: "the run's probe, the planner's (the flown one reads latents and each step's thrusts): a planner component",
    THRUST_ONLY: "the run's probe retrained on each step's thrusts alone, no latent",
    "physics": "the rigid-body model fed the logged thrusts",
    "constant_velocity": "constant velocity: world-frame velocity, body rates and fuel held",
}
PLANNER_HISTORY = 2  # latents the planner's world model sees per imagined step (the cpu planner preset)
TABLE1_JSON, TABLE1_MD = "table1.json", "table1.md"
CHOICE_FILE = "latent_probe.json"  # in the run folder: the candidate chosen on the validation episodes

Physics = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]  # state0 (K, 16), thrusts (K, n, 8) -> (K, n, 16)


def table_histories(model_history: int, asked: int | None = None) -> list[int]:
    """The planner's history and the model's own (and ``asked``, when another)."""
    return sorted({min(PLANNER_HISTORY, model_history), model_history} | ({asked} if asked else set()))


@dataclass
class Rows:
    """The probes of one Table I and the rows left out."""

    probes: dict[str, PhysicsProbe]  # row (or, on validation, candidate) -> probe
    missing: dict[str, str] = field(default_factory=dict)  # row -> why it is left out, and the fix
    candidates: list[str] = field(default_factory=list)  # validation: the latent_probe candidates scored
    choice: dict | None = None  # test: the choice the latent_probe row follows


def _choose_command(run) -> str:
    return f"orbitmodel eval probe {run} DATASET --split val"


def _untrained(run_dir) -> str:
    return (
        f"no {LATENT} candidate is trained; train them with `{train_command(run_dir, next(iter(CANDIDATES)))}` "
        f"and the other {LATENT}-* variants, then choose with `{_choose_command(run_dir)}`"
    )


def load_rows(run_dir: Path, world_model, flown: PhysicsProbe, split: str, device) -> Rows:
    """The run's probes for Table I on ``split``: the flown one, the paper's and the thrust-only
    one when trained; on "val" every trained latent_probe candidate (to choose among), on "test"
    the chosen one (``CHOICE_FILE``)."""
    run_dir, fp = Path(run_dir), world_model.fingerprint

    def load(variant):
        return PhysicsProbe.from_pretrained(run_dir, world_model=fp, variant=variant).to(device)

    rows = Rows(probes={})
    for row in (PAPER_PROBE, THRUST_ONLY):
        try:
            rows.probes[row] = load(row)
        except RunError as err:
            rows.missing[row] = str(err)
    rows.probes[FLOWN] = flown
    trained = [c for c in CANDIDATES if (probe_folder(run_dir, "latent", c) / CONFIG).is_file()]
    if split == "val":
        for c in trained:
            try:
                rows.probes[c] = load(c)
                rows.candidates.append(c)
            except RunError as err:
                rows.missing[c] = str(err)
        if not rows.candidates:
            rows.missing[LATENT] = _untrained(run_dir)
        return rows
    try:
        rows.choice, rows.probes[LATENT] = load_choice(run_dir, fp, device)
    except RunError as err:
        rows.missing[LATENT] = str(err)
    return rows


def load_choice(run_dir: Path, world_model: str, device="cpu") -> tuple[dict, PhysicsProbe]:
    """The ``latent_probe`` chosen on the validation episodes (``CHOICE_FILE``) and its probe, for the
    test split's row and for the planner (``--set probe=latent_probe``). RunError naming the fix when
    none is chosen, or the choice was made for another world model (a weights fingerprint) or
    before its probe was trained again."""
    run_dir = Path(run_dir)
    path = run_dir / CHOICE_FILE
    if not path.is_file():
        trained = [c for c in CANDIDATES if (probe_folder(run_dir, "latent", c) / CONFIG).is_file()]
        raise RunError(
            f"no {LATENT} chosen among the {len(trained)} trained candidates; "
            f"choose it with `{_choose_command(run_dir)}`"
            if trained
            else _untrained(run_dir)
        )
    choice = json.loads(path.read_text())
    probe = PhysicsProbe.from_pretrained(run_dir, world_model=world_model, variant=choice["chosen"]).to(device)
    if choice.get("world_model") != world_model or choice.get("probe") != fingerprint(probe.state_dict()):
        raise RunError(
            f"{path} chose {choice['chosen']} for another world model or before it was trained again; "
            f"choose again with `{_choose_command(run_dir)}`"
        )
    return choice, probe


@torch.no_grad()
def predict_rows(
    world_model, probes: dict[str, PhysicsProbe], batch: dict, context: int, n: int, device, histories, physics=None
) -> dict:
    """{"truth": (K, n, 16), "shared": {row: (K, n, 16)}, "by_history": {history: {row: (K, n, 16)}}}
    for windows (K, context + n, ...): every probe reads the latents imagined at each history (and
    its own share of them: the thrust-only probe none) and every frame's state as the planner reads
    it (:meth:`PhysicsProbe.per_frame`); the shared rows read the logged thrusts or nothing."""
    m, s = context, world_model.config.frame_step
    images, states, actions = (batch[k].to(device) for k in (S.IMAGE, S.STATE, S.ACTION))
    z = world_model.encode(images[:, :m:s], states[:, :m:s])  # (K, context steps, D)
    steps = group_actions(actions[:, : m - 1 + n], s)  # (K, context steps - 1 + n / s, 8 s): taken, then imagined
    future, state0 = steps[:, -(n // s) :], states[:, m - 1]  # the imagined steps' thrusts; the true state at t
    by_history = {}
    for h in histories:
        z_future = world_model.rollout(z, steps, h)  # (K, n / s, D)
        by_history[h] = {row: p.per_frame(z_future, state0, z[:, -1], s, future).cpu() for row, p in probes.items()}
    shared = {"constant_velocity": constant_velocity(state0, n, S.DT).cpu()}
    if physics is not None:
        shared["physics"] = physics(state0.float().cpu(), actions[:, m - 1 : m - 1 + n].float().cpu())
    return {"truth": states[:, m : m + n].float().cpu(), "shared": shared, "by_history": by_history}


def add_errors(errors: dict, pred: dict) -> None:
    """Append one batch's per-step errors: errors[history][row][quantity] -> list of (K, n)."""
    for h, per_row in pred["by_history"].items():
        for row, states in {**per_row, **pred["shared"]}.items():
            for q, e in step_errors(states, pred["truth"]).items():
                errors.setdefault(h, {}).setdefault(row, {}).setdefault(q, []).append(e)


def reference(table: dict, q: str, h: int) -> float:
    """What a candidate's cell is scored against: the paper's figure, or where the paper has none
    (another horizon), constant velocity's on the same windows."""
    return PAPER[h][q] if h in PAPER else table["constant_velocity"][q][f"h{h}"]["mean"]


def score(by_history: dict, row: str, horizons) -> dict:
    """A row's cells at or below the reference, and the geometric mean of its ratios to it, over
    every history, quantity and horizon."""
    met, logs = 0, []
    for entry in by_history.values():
        t = entry["table"]
        for q in QUANTITIES:
            for h in horizons:
                mine, ref = t[row][q][f"h{h}"]["mean"], reference(t, q, h)
                met += mine <= ref
                logs.append(math.log(max(mine, 1e-12) / max(ref, 1e-12)))
    return {"met": met, "cells": len(logs), "ratio": math.exp(sum(logs) / len(logs))}


def build(rows: Rows, errors: dict, horizons, facts: dict) -> dict:
    """The Table I result: ``facts`` (run, windows, ...) with ``by_history[str(h)]["table"]``, today's
    probe-table shape (row -> quantity -> hH -> mean, std, at_h, at_h_std), per history; on the
    validation split, the candidates' scores and the chosen one, which is the latent_probe row."""
    by_history = {
        str(h): {
            "history": h,
            "table": summarise({r: {q: torch.cat(v) for q, v in e.items()} for r, e in per.items()}, horizons),
        }
        for h, per in sorted(errors.items())
    }
    result = {**facts, "histories": sorted(errors), "by_history": by_history}
    if rows.candidates:
        scores = {c: score(by_history, c, horizons) for c in rows.candidates}
        chosen = max(rows.candidates, key=lambda c: (scores[c]["met"], -scores[c]["ratio"]))
        for entry in by_history.values():
            entry["table"][LATENT] = entry["table"][chosen]
        result[LATENT] = {"chosen": chosen, "scores": scores}
    elif rows.choice is not None:
        result[LATENT] = {
            "chosen": rows.choice["chosen"],
            "chosen_on": {k: rows.choice[k] for k in ("split", "windows", "seed")},
        }
    present = [r for r in ROWS if r in by_history[str(result["histories"][0])]["table"]]
    result["rows"] = {r: ROWS[r] for r in present}
    result["probes"] = {r: _described(v, rows.probes[k]) for r, (v, k) in _variants(rows, result).items()}
    result["missing"] = {r: note for r, note in rows.missing.items() if r in ROWS or r in CANDIDATES}
    return result


def _variants(rows: Rows, result: dict) -> dict[str, tuple[str, str]]:
    """row -> (the variant it reads, its key in ``rows.probes``)."""
    out = {r: (r, r) for r in (PAPER_PROBE, FLOWN, THRUST_ONLY) if r in rows.probes}
    if rows.candidates:
        out[LATENT] = (result[LATENT]["chosen"], result[LATENT]["chosen"])
        out.update({c: (c, c) for c in rows.candidates})
    elif LATENT in rows.probes:
        out[LATENT] = (rows.choice["chosen"], LATENT)
    return out


def _described(variant: str, probe: PhysicsProbe) -> dict:
    c = probe.config
    return {"folder": folder_name(variant), "inputs": c.inputs, "integrator": c.integrator, "per_frame": c.substeps > 1}


def save_choice(run_dir: Path, result: dict, rows: Rows, world_model_print: str) -> Path:
    """Record the validation choice in the run, for the test split's latent_probe row."""
    chosen = result[LATENT]["chosen"]
    choice = {
        "chosen": chosen,
        "split": result["split"],
        "windows": result["windows"],
        "seed": result["seed"],
        "histories": result["histories"],
        "horizons": result["horizons"],
        "world_model": world_model_print,
        "probe": fingerprint(rows.probes[chosen].state_dict()),
        "scores": result[LATENT]["scores"],
        "rule": "most cells at or below the reference (the paper's figure, else constant velocity), then the "
        "smallest geometric mean of the ratios to it, over every history, quantity and horizon",
    }
    path = Path(run_dir) / CHOICE_FILE
    write_json_atomic(path, choice)
    return path


def _cell(entry: dict) -> str:
    return f"{entry['mean']:.4f} ({entry['at_h']:.4f})"


def markdown(result: dict) -> str:
    """One table per history: a column per row beside the paper's figure, each cell the MAE over
    frames 1..h (in brackets, at frame h); then the rows left out, and on validation the candidates."""
    rows = list(result["rows"])
    lines = [
        f"Table I: {result['windows']} collision-free {result['split']} windows (seed {result['seed']}), context "
        f"{result['context']} frames, the world model stepping {result['frame_step']} frame(s); each cell is the MAE "
        "over frames 1..h averaged over the windows, with the error at frame h in brackets (dt = 0.04 s).",
        f"World model: `{result['run']}` (preset {result['preset']}); dataset `{result['dataset']}`.",
        "",
        *(f"- `{r}`: {label}" for r, label in result["rows"].items()),
    ]
    for key in map(str, result["histories"]):
        t = result["by_history"][key]["table"]
        lines += [
            "",
            f"The world model seeing {key} latents per imagined step"
            + (" (as the planner flies)" if int(key) == PLANNER_HISTORY else "")
            + ":",
            "",
            "| quantity | h | paper | " + " | ".join(rows) + " |",
            "|---|---|---|" + "---|" * len(rows),
        ]
        for q, unit in QUANTITIES.items():
            for h in result["horizons"]:
                paper = PAPER.get(h, {}).get(q)
                cells = " | ".join(_cell(t[r][q][f"h{h}"]) for r in rows)
                lines.append(
                    f"| {q.replace('_', ' ')} ({unit}) | {h} | {'-' if paper is None else f'{paper:.4f}'} | {cells} |"
                )
    if result["missing"]:
        lines += ["", *(f"Left out, `{r}`: {note}" for r, note in result["missing"].items())]
    if LATENT in result and "scores" in result[LATENT]:
        chosen = result[LATENT]["chosen"]
        lines += [
            "",
            f"`{LATENT}` candidates on these windows (cells at or below the paper, else constant velocity; "
            "geometric mean of the ratios to it):",
            "",
            "| candidate | cells met | ratio | |",
            "|---|---|---|---|",
        ]
        for c, sc in sorted(result[LATENT]["scores"].items(), key=lambda kv: (-kv[1]["met"], kv[1]["ratio"])):
            lines.append(
                f"| {c} | {sc['met']} of {sc['cells']} | {sc['ratio']:.3f} | {'chosen' if c == chosen else ''} |"
            )
    elif LATENT in result:
        on = result[LATENT]["chosen_on"]
        lines += ["", f"`{LATENT}` is {result[LATENT]['chosen']}, chosen on {on['windows']} {on['split']} windows."]
    return "\n".join(lines) + "\n"
