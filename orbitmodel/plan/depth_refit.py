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
from orbitmodel.plan.depth_recipe import DepthRefitConfig
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

FOLDER = "depth"
EVAL = "eval.json"


def depth_folder(run: str | Path) -> Path:
    return Path(run) / FOLDER


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


def refit_depth_head(
    run: str | Path, dataset: str, cfg: DepthRefitConfig = DepthRefitConfig(), overwrite: bool = False
) -> dict:
    """Refit ``run``'s depth head (see the module docstring); returns the before/after evaluation."""
    out = depth_folder(local_run_folder(run, "a depth refit"))
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
    for name, h in (("stage1", model.depth_head), ("refit", head)):
        pred = _predict(h, test_x, scale)
        result[name] = {
            "mae_m": float((pred - test_d).abs().mean()),
            **depth_by_band(pred, test_d, seen_within=cfg.near_m),
        }
    RunDir(out).start(
        run_config(DEPTH_REFIT, refit=asdict(cfg), dataset=str(dataset), world_model=model.fingerprint),
        resume=False,
        overwrite=True,
    )
    RunDir(out).save_final(head.state_dict(), steps)
    write_json_atomic(out / EVAL, result)
    return result


def load_refit_head(run: str | Path, model):
    """The refitted depth head of ``run`` (a copy of ``model.depth_head`` with its weights), or
    RunError with the command that makes it."""
    folder = depth_folder(run)
    if not (folder / WEIGHTS).is_file() or not (folder / CONFIG).is_file():
        raise RunError(
            f"{run} has no refitted depth head ({folder} is missing); fit one with `orbitmodel depth {run} DATASET`"
        )
    made_on = RunDir(folder).read_config().get("world_model")  # refits before fingerprints have none
    if made_on is not None and made_on != getattr(model, "fingerprint", made_on):
        raise RunError(
            f"{folder} was refitted on another world model than {run} holds now; fit it again with "
            f"`orbitmodel depth {run} DATASET --overwrite`"
        )
    head = copy.deepcopy(model.depth_head)
    try:
        head.load_state_dict(load_weights(folder))
    except RuntimeError as err:
        raise RunError(
            f"{folder / WEIGHTS} does not fit this run's depth head ({str(err).splitlines()[0]}); "
            f"fit it again with `orbitmodel depth {run} DATASET --overwrite`"
        ) from None
    return head.eval()


def refit_head_for(run: str | Path, model, choice: str):
    """The depth head a planner flies with: the refitted one for ``choice`` "refit" (RunError if
    the run has none), "auto" (if there is one), or None for the Stage I head ("stage1", or
    "auto" without a refit)."""
    if choice == "stage1" or (choice == "auto" and not (depth_folder(run) / WEIGHTS).is_file()):
        return None
    return load_refit_head(run, model)
