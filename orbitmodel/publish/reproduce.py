"""The model card's "Reproduce" commands: each training command of a pushed run with a flag for
every setting in which the run differs from what the command gives without flags (its preset, its
preset's probe recipe, the depth refit's defaults), so that running them writes the run's configs
again. A difference that no flag sets is named in a comment after the command (config.json
records it), and so is a preset that is not built in."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Callable

from orbitmodel.runs import CONFIG

Flag = Callable[[object], list[str]]  # a setting's value -> the command-line words that set it


def _text(value) -> str:
    """A value as a flag takes it: exact floats (100.0 -> 100), comma-separated sequences."""
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() else repr(value)
    if isinstance(value, (list, tuple)):
        return ",".join(_text(v) for v in value)
    return str(value)


def option(name: str) -> Flag:
    return lambda value: [f"{name} {_text(value)}"]


def switch(name: str) -> Flag:
    return lambda value: [f"--{name}" if value else f"--no-{name}"]


def repeated(name: str) -> Flag:
    return lambda values: [f"{name} {v}" for v in values]


LOOP = {
    "train.loop.epochs": option("--epochs"),
    "train.loop.max_steps": option("--max-steps"),
    "train.loop.batch_size": option("--batch-size"),
    "train.loop.lr": option("--lr"),
    "train.loop.num_workers": option("--workers"),
    "train.loop.seed": option("--seed"),
}
DATA = {"levels": repeated("--level"), "outcomes": repeated("--outcome")}
STAGE1 = {
    "model.frame_step": option("--frame-step"),
    "model.lambda_sigreg": option("--lambda-sigreg"),
    "model.sigreg_pool": switch("sigreg-pool"),
    **LOOP,
    "train.val_fraction": option("--val-fraction"),
    **DATA,
}
PROBE = {
    "inputs": option("--inputs"),
    "integrator": option("--integrator"),
    "per_frame": switch("per-frame"),
    **LOOP,
    "train.weights": option("--loss-weights"),
    "train.increment_weight": option("--increment-weight"),
    "train.cache_windows": option("--cache-windows"),
}
DEPTH = {
    name: option("--" + name.replace("_", "-"))
    for name in ("frames", "test_frames", "epochs", "lr", "near_weight", "near_m", "seed", "eval_split")
}
POLICY = {
    **LOOP,
    "train.pad_before": option("--pad-before"),
    "train.mask_padding": switch("mask-padding"),
    "train.val_fraction": option("--val-fraction"),
    **DATA,
}
NOT_SETTINGS = ("name", "description")  # a preset's text, not how it trains


def _leaves(d: dict, prefix: str = "") -> dict[str, object]:
    """Dotted paths to the values of nested dicts, as JSON reads them back (tuples are lists)."""
    out = {}
    for key, value in json.loads(json.dumps(d)).items():
        if isinstance(value, dict):
            out.update(_leaves(value, f"{prefix}{key}."))
        elif f"{prefix}{key}" not in NOT_SETTINGS:
            out[f"{prefix}{key}"] = value
    return out


def command(base: str, run: dict, default: dict, flags: dict[str, Flag]) -> str:
    """``base`` with the flags that turn ``default`` (the settings ``base`` gives alone) into ``run``."""
    got, given = _leaves(run), _leaves(default)
    changed = {k: v for k, v in got.items() if k in given and given[k] != v}
    words = [base] + [w for key, flag in flags.items() if key in changed for w in flag(changed[key])]
    unflagged = [f"{k}={_text(v)}" for k, v in changed.items() if k not in flags]
    return " ".join(words) + (
        f"   # no flag sets {', '.join(unflagged)} (config.json records every setting)" if unflagged else ""
    )


def _read(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.is_file() else None


def train_command(raw: dict) -> str:
    """``orbitmodel train`` for a Stage I run's config.json ``raw``."""
    from orbitmodel.config import PRESETS, Preset

    preset = Preset.from_dict(raw["preset"])
    base = f"orbitmodel train DATA --preset {preset.name} --out RUN"
    if preset.name not in PRESETS:
        return base + f'   # {preset.name!r} is no built-in preset: config.json\'s "preset" holds its settings'
    if raw["dataset"]["image_size"] != preset.model.image_size:
        base += " --resize"
    run = {**preset.to_dict(), "levels": raw.get("levels", []), "outcomes": raw.get("outcomes", [])}
    return command(base, run, {**PRESETS[preset.name]().to_dict(), "levels": [], "outcomes": []}, STAGE1)


def probe_command(raw: dict, probe: dict, kind: str) -> str:
    """``orbitmodel probe`` for a Stage I run's config.json ``raw`` and its probe's ``probe`` (of ``kind``)."""
    from orbitmodel.config import Preset
    from orbitmodel.probe.train import upgrade_probe_config

    recipe = Preset.from_dict(raw["preset"]).probe
    probe = upgrade_probe_config(probe)
    net = probe["probe"]
    run = {"integrator": net["integrator"], "hidden": net["hidden"], "layers": net["layers"], "train": probe["train"]}
    default = {
        "integrator": recipe.integrator,
        "hidden": recipe.hidden,
        "layers": recipe.layers,
        "train": recipe.train.to_dict(),
    }
    if kind == "latent":
        run.update(inputs=net["inputs"], per_frame=net["substeps"] > 1)
        default.update(inputs=recipe.inputs, per_frame=recipe.per_frame and raw["preset"]["model"]["frame_step"] > 1)
    base = "orbitmodel probe RUN DATA" + (" --state-only" if kind == "state" else "")
    return command(base, run, default, PROBE)


def depth_command(depth: dict) -> str:
    """``orbitmodel depth`` for a depth refit's config.json ``depth``."""
    from orbitmodel.plan.depth_recipe import DepthRefitConfig

    return command("orbitmodel depth RUN DATA", depth["refit"], asdict(DepthRefitConfig()), DEPTH)


def stage1_commands(run: Path, raw: dict) -> list[str]:
    """The training commands of a Stage I run and the sub-runs it holds (probes, depth refit)."""
    lines = [train_command(raw)]
    for folder, kind in (("probe", "latent"), ("probe-state", "state")):
        probe = _read(run / folder / CONFIG)
        if probe is not None:
            lines.append(probe_command(raw, probe, kind))
    depth = _read(run / "depth" / CONFIG)
    if depth is not None:
        lines.append(depth_command(depth))
    return lines


def policy_command(raw: dict) -> str:
    """``orbitmodel train-policy`` for a policy run's config.json ``raw``."""
    from orbitmodel.baselines.diffusion.config import POLICY_PRESETS, PolicyPreset
    from orbitmodel.baselines.diffusion.train import DEFAULT_LEVELS

    preset = PolicyPreset.from_dict(raw["preset"])
    base = f"orbitmodel train-policy DATA --preset {preset.name} --out RUN"
    if preset.name not in POLICY_PRESETS:
        return base + f'   # {preset.name!r} is no built-in preset: config.json\'s "preset" holds its settings'
    run = {**preset.to_dict(), "levels": raw.get("levels", list(DEFAULT_LEVELS)), "outcomes": raw.get("outcomes", [])}
    default = {**POLICY_PRESETS[preset.name]().to_dict(), "levels": list(DEFAULT_LEVELS), "outcomes": []}
    return command(base, run, default, POLICY)
