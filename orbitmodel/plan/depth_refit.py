"""Refit the depth head for the planner: the run's encoder frozen, the loss weighted towards near cells.

Stage I trains the depth head with upstream's MSE on depth / depth_max. Most of the 16x16 cells
are sky at the far plane (50 m), so that loss is mostly about the sky, and the head misses many
near cells (``orbitmodel eval rollout`` reports them by band, ``plan.depth_bands``); the planner
does not plan around what it does not see. The refit keeps the architecture and starts from the
Stage I head, reads the frozen encoder's patch tokens of ``frames`` random training frames
(encoded once), and minimises

    mean_cells (1 + near_weight [d < near_m]) (pred - d)^2 / depth_max^2

It writes ``RUN/depth/`` (config.json, model.safetensors, eval.json). The latents, and so the
dynamics and the probe, do not change; the planner uses this head when it is there
(``PlannerConfig.depth_head``).
"""

from __future__ import annotations

import copy
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from orbitdata import schema as S
from orbitmodel.data import read_dataset_meta, split_selection, training_episodes
from orbitmodel.model.world_model import WorldModel, images_to_float
from orbitmodel.plan.depth_bands import depth_by_band
from orbitmodel.plan.depth_recipe import CHOICES, MAX_RANGE, DepthRefitConfig, head_folder
from orbitmodel.runs import (
    CONFIG,
    DEPTH_REFIT,
    WEIGHTS,
    RunDir,
    RunError,
    check_image_size,
    load_weights,
    local_run_folder,
    run_config,
    write_json_atomic,
)

EVAL = "eval.json"


def depth_folder(run: str | Path, name: str = "") -> Path:
    """RUN/depth, or RUN/depth-NAME for a head named ``name`` (refitted on another dataset's frames)."""
    return Path(run) / head_folder(name)


def _patches(
    model, dataset: str, split: str, n: int, seed: int, where: str, episodes=None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Patch tokens (n, P, width) float16 and true depth (n, 16, 16) of n random frames of ``split``."""
    from orbitdata.load import load_windows

    frames = load_windows(dataset, split=split, context=1, horizon=0, columns=[S.IMAGE, S.DEPTH_LOW], episodes=episodes)
    if len(frames) < n:
        raise RunError(
            f"the {split} split of {dataset} has {len(frames)} frames, fewer than the {n} asked; "
            f"pass {where} {len(frames)} or less"
        )
    idx = np.sort(np.random.default_rng(seed).choice(len(frames), n, replace=False))
    tokens, depth = [], []
    with torch.no_grad():
        for start in range(0, n, 256):
            batch = [frames[int(i)] for i in idx[start : start + 256]]
            _, p = model.encoder(images_to_float(torch.stack([b[S.IMAGE][0] for b in batch])))
            tokens.append(p.half())
            depth.append(torch.stack([b[S.DEPTH_LOW][0] for b in batch]))
    return torch.cat(tokens), torch.cat(depth)


def fit_near_weighted(head, inputs: torch.Tensor, depth: torch.Tensor, cfg, scale: float) -> tuple[int, list[float]]:
    """Train ``head`` (inputs (N, ...) -> depth / ``scale``) on the true ``depth`` (N, 16, 16) metres
    with the near cells weighted (module docstring): AdamW, cosine decay to zero, batches drawn in
    a seeded order. ``cfg`` gives epochs, batch_size, lr, near_weight, near_m and seed (the refit's
    and the imagined-depth fit's recipes). Returns the optimiser steps and each epoch's last loss;
    the head is left in eval mode."""
    steps_per_epoch = max(1, len(inputs) // cfg.batch_size)
    opt = torch.optim.AdamW(head.parameters(), lr=cfg.lr, weight_decay=0.0)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.epochs * steps_per_epoch)
    g = torch.Generator().manual_seed(cfg.seed)
    losses = []
    with torch.enable_grad():
        for _ in range(cfg.epochs):
            order = torch.randperm(len(inputs), generator=g)
            for s in range(steps_per_epoch):
                i = order[s * cfg.batch_size : (s + 1) * cfg.batch_size]
                pred, true = head(inputs[i].float()) * scale, depth[i]
                weight = 1 + cfg.near_weight * (true < cfg.near_m).float()
                loss = (weight * (pred - true) ** 2).mean() / scale**2
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                sched.step()
            losses.append(float(loss.detach()))
    head.eval()
    return cfg.epochs * steps_per_epoch, losses


def _predict(head, tokens: torch.Tensor, scale: float) -> torch.Tensor:
    with torch.no_grad():
        return torch.cat([head(tokens[s : s + 512].float()) for s in range(0, len(tokens), 512)]) * scale


def _score(head, tokens: torch.Tensor, depth: torch.Tensor, scale: float, near_m: float) -> dict:
    """MAE and :func:`depth_by_band` of ``head`` on encoded frames against their true depth."""
    pred = _predict(head, tokens, scale)
    return {"mae_m": float((pred - depth).abs().mean()), **depth_by_band(pred, depth, seen_within=near_m)}


def score_heads(run: str | Path, dataset: str, names, split: str = "val", frames: int = 4000, seed: int = 1) -> dict:
    """Each depth head of ``run`` that ``names`` gives (stage1, refit, or a NAME of RUN/depth-NAME)
    scored on the same ``frames`` random frames of ``dataset``'s ``split`` ("val": the run's
    validation episode numbers, "test"): {name: MAE and :func:`depth_by_band`}. With seed 1 and a
    refit's --test-frames, they are the frames its own before/after table scored."""
    model = WorldModel.from_pretrained(run)
    check_image_size(read_dataset_meta(dataset), model.config.image_size, f"the world model of {run}")
    heads = {
        name: model.depth_head if name == "stage1" else load_refit_head(run, model, "" if name == "refit" else name)
        for name in names
    }
    where, episodes = split_selection(split, model.run.validation)
    tokens, depth = _patches(model, dataset, where, frames, seed, "--frames", episodes)
    scale = float(model.depth_scale)
    return {name: _score(head, tokens, depth, scale, MAX_RANGE) for name, head in heads.items()}


def refit_depth_head(
    run: str | Path, dataset: str, cfg: DepthRefitConfig = DepthRefitConfig(), overwrite: bool = False, name: str = ""
) -> dict:
    """Refit ``run``'s depth head (see the module docstring) into RUN/depth, or RUN/depth-NAME for
    ``name``; returns the before/after evaluation."""
    out = depth_folder(local_run_folder(run, "a depth refit"), name)
    if (out / WEIGHTS).exists() and not overwrite:
        raise RunError(f"{out} already holds a refitted depth head; pass --overwrite to fit it again")
    model = WorldModel.from_pretrained(run)
    check_image_size(read_dataset_meta(dataset), model.config.image_size, f"the world model of {run}")
    start = time.perf_counter()
    held_out = model.run.validation  # the run's validation episodes: never fitted, scored with eval_split "val"
    train_x, train_d = _patches(
        model, dataset, "train", cfg.frames, cfg.seed, "--frames", training_episodes(dataset, (), (), held_out)
    )
    split, episodes = split_selection(cfg.eval_split, held_out)
    test_x, test_d = _patches(model, dataset, split, cfg.test_frames, cfg.seed + 1, "--test-frames", episodes)
    encoded = time.perf_counter() - start
    scale = float(model.depth_scale)
    head = copy.deepcopy(model.depth_head).train()
    for p in head.parameters():
        p.requires_grad_(True)
    steps, losses = fit_near_weighted(head, train_x, train_d, cfg, scale)
    result = {
        "run": str(run),
        "dataset": str(dataset),
        "config": asdict(cfg),
        "seconds": {"encode": encoded, "fit": time.perf_counter() - start - encoded},
        "epoch_loss": losses,
    }
    for label, h in (("stage1", model.depth_head), ("refit", head)):
        result[label] = _score(h, test_x, test_d, scale, cfg.near_m)
    RunDir(out).start(
        run_config(DEPTH_REFIT, refit=asdict(cfg), dataset=str(dataset), world_model=model.fingerprint),
        resume=False,
        overwrite=True,
    )
    RunDir(out).save_final(head.state_dict(), steps)
    write_json_atomic(out / EVAL, result)
    return result


def load_refit_head(run: str | Path, model, name: str = ""):
    """The refitted depth head of ``run`` (RUN/depth, or RUN/depth-NAME for ``name``: a copy of
    ``model.depth_head`` with its weights), or RunError with the command that makes it."""
    folder = depth_folder(run, name)
    again = f"`orbitmodel depth {run} DATASET{f' --name {name}' if name else ''}"
    if not (folder / WEIGHTS).is_file() or not (folder / CONFIG).is_file():
        raise RunError(f"{run} has no refitted depth head ({folder} is missing); fit one with {again}`")
    made_on = RunDir(folder).read_config().get("world_model")  # refits before fingerprints have none
    if made_on is not None and made_on != getattr(model, "fingerprint", made_on):
        raise RunError(
            f"{folder} was refitted on another world model than {run} holds now; fit it again with {again} --overwrite`"
        )
    head = copy.deepcopy(model.depth_head)
    try:
        head.load_state_dict(load_weights(folder))
    except RuntimeError as err:
        raise RunError(
            f"{folder / WEIGHTS} does not fit this run's depth head ({str(err).splitlines()[0]}); "
            f"fit it again with {again} --overwrite`"
        ) from None
    return head.eval()


def refit_head_for(run: str | Path, model, choice: str):
    """The depth head a planner flies with: the refitted one for ``choice`` "refit" (RunError if
    the run has none), "auto" (if there is one), the one named ``choice`` (RUN/depth-NAME), or None
    for the Stage I head ("stage1", or "auto" without a refit)."""
    if choice == "stage1" or (choice == "auto" and not (depth_folder(run) / WEIGHTS).is_file()):
        return None
    return load_refit_head(run, model, "" if choice in CHOICES else choice)


def head_source(choice: str, head) -> str:
    """What a pilot's metadata calls its depth head: stage1, refit, or refit-NAME."""
    if head is None:
        return "stage1"
    return "refit" if choice in CHOICES else f"refit-{choice}"
