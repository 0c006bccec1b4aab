"""Fit the head that reads depth out of imagined latents (``orbitmodel depth --imagined``).

The frozen world model encodes ``context`` frames of a training window, as the planner does, and
imagines the next ``horizon`` frames' latents from the thrusts actually taken. The head
(:class:`~orbitmodel.plan.imagined.ImaginedDepthHead`) learns to read each latent, the last
encoded one and every imagined one, as that frame's ``depth_low``, with the refit's weighting of
the near cells (``plan.depth_refit``)::

    mean_cells (1 + near_weight [d < near_m]) (pred - d)^2 / depth_max^2

so it is scored on what the planner will read: latents the predictor made up, not encoded ones.
It writes ``RUN/depth-imagined/`` (config.json, model.safetensors, eval.json with the error by
depth band at each step ahead on ``eval_split``'s windows).
"""

from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from orbitdata import schema as S
from orbitmodel.data import load_model_windows, read_dataset_meta, split_selection, training_episodes
from orbitmodel.model.world_model import WorldModel
from orbitmodel.plan.depth_bands import depth_by_band
from orbitmodel.plan.depth_recipe import ImaginedDepthConfig
from orbitmodel.plan.depth_refit import fit_near_weighted
from orbitmodel.plan.imagined import ImaginedDepth, ImaginedDepthHead
from orbitmodel.runs import (
    CONFIG,
    WEIGHTS,
    RunDir,
    RunError,
    check_image_size,
    load_weights,
    local_run_folder,
    run_config,
    write_json_atomic,
)

COLUMNS = (S.IMAGE, S.STATE, S.ACTION, S.DEPTH_LOW)  # what the fit reads: nothing privileged
FOLDER = "depth-imagined"
EVAL = "eval.json"
STAGE = "depth_imagined"


def imagined_folder(run: str | Path) -> Path:
    return Path(run) / FOLDER


@torch.no_grad()
def imagine_depth_pairs(
    model: WorldModel, dataset: str, split: str, n: int, cfg: ImaginedDepthConfig, seed: int, where: str, episodes=None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Latents (n, 1 + steps, D), the last encoded then the imagined ones, and their frames' true
    depth (n, 1 + steps, 16, 16) metres, of n random windows of ``split``."""
    from orbitdata.load import collate_windows

    step = model.config.frame_step
    if cfg.horizon % step:
        raise RunError(
            f"the imagined-depth fit covers {cfg.horizon} frames, which the run's steps of {step} frames do "
            "not divide; fit it on a run whose frame step divides the planner's horizon"
        )
    steps = cfg.horizon // step
    windows = load_model_windows(
        dataset,
        step,
        split=split,
        context=cfg.context,
        horizon=steps,
        columns=list(COLUMNS),
        episodes=episodes,
    )
    if len(windows) < n:
        raise RunError(
            f"the {split} split of {dataset} has {len(windows)} windows, fewer than {n}; pass {where} {len(windows)} or less"
        )
    chosen = np.sort(np.random.default_rng(seed).choice(len(windows), n, replace=False))
    latents, depth = [], []
    for start in range(0, n, 64):
        batch = collate_windows(windows.__getitems__([int(i) for i in chosen[start : start + 64]]))
        z = model.encode(batch[S.IMAGE][:, : cfg.context], batch[S.STATE][:, : cfg.context])  # (b, c, D)
        future = model.rollout(z, batch[S.ACTION][:, :-1].float(), cfg.context)  # (b, steps, D)
        latents.append(torch.cat([z[:, -1:], future], 1))
        depth.append(batch[S.DEPTH_LOW][:, cfg.context - 1 :].float())  # (b, 1 + steps, 16, 16)
    return torch.cat(latents), torch.cat(depth)


def _scores(depth: ImaginedDepth, z: torch.Tensor, true: torch.Tensor, near_m: float) -> list[dict]:
    """Per step ahead (0: the encoded frame): MAE and the bands of :func:`depth_by_band`."""
    pred = torch.cat([depth.maps(z[i : i + 512]) for i in range(0, len(z), 512)])
    return [
        {
            "step": k,
            "mae_m": float((pred[:, k] - true[:, k]).abs().mean()),
            **depth_by_band(pred[:, k], true[:, k], seen_within=near_m),
        }
        for k in range(z.shape[1])
    ]


def fit_imagined_depth(
    run: str | Path, dataset: str, cfg: ImaginedDepthConfig = ImaginedDepthConfig(), overwrite: bool = False
) -> dict:
    """Fit ``run``'s imagined-depth head (see the module docstring); returns its evaluation."""
    out = imagined_folder(local_run_folder(run, "an imagined-depth fit"))
    if (out / WEIGHTS).exists() and not overwrite:
        raise RunError(f"{out} already holds an imagined-depth head; pass --overwrite to fit it again")
    model = WorldModel.from_pretrained(run).eval()
    check_image_size(read_dataset_meta(dataset), model.config.image_size, f"the world model of {run}")
    if not 1 <= cfg.context <= model.config.history:
        raise RunError(
            f"--context {cfg.context}: the world model of {run} rolls out from 1..{model.config.history} latents"
        )
    start = time.perf_counter()
    held_out = model.run.validation
    train_z, train_d = imagine_depth_pairs(
        model, dataset, "train", cfg.windows, cfg, cfg.seed, "--frames", training_episodes(dataset, (), (), held_out)
    )
    split, episodes = split_selection(cfg.eval_split, held_out)
    test_z, test_d = imagine_depth_pairs(
        model, dataset, split, cfg.test_windows, cfg, cfg.seed + 1, "--test-frames", episodes
    )
    imagined = time.perf_counter() - start
    scale = float(model.depth_scale)
    torch.manual_seed(cfg.seed)
    head = ImaginedDepthHead(model.config.latent_dim, cfg.hidden)
    x, y = train_z.flatten(0, 1), train_d.flatten(0, 1)  # every latent, encoded or imagined, is a sample
    steps, losses = fit_near_weighted(head, x, y, cfg, scale)
    result = {
        "run": str(run),
        "dataset": str(dataset),
        "config": asdict(cfg),
        "frame_step": model.config.frame_step,
        "seconds": {"imagine": imagined, "fit": time.perf_counter() - start - imagined},
        "epoch_loss": losses,
        "eval_split": cfg.eval_split,
        "steps": _scores(ImaginedDepth(head, scale), test_z, test_d, cfg.near_m),
    }
    folder = RunDir(out)
    folder.start(
        run_config(STAGE, imagined=asdict(cfg), dataset=str(dataset), world_model=model.fingerprint),
        resume=False,
        overwrite=True,
    )
    folder.save_final(head.state_dict(), steps)
    write_json_atomic(out / EVAL, result)
    return result


def load_imagined_depth(run: str | Path, model, timings=None) -> ImaginedDepth:
    """The fitted imagined-depth head of ``run`` for ``model``, or RunError with the command that makes it."""
    folder = imagined_folder(run)
    if not (folder / WEIGHTS).is_file() or not (folder / CONFIG).is_file():
        raise RunError(
            f"{run} has no imagined-depth head ({folder} is missing); fit one with "
            f"`orbitmodel depth {run} DATASET --imagined`"
        )
    config = RunDir(folder).read_config()
    if config.get("world_model") != getattr(model, "fingerprint", None):
        raise RunError(
            f"{folder} was fitted on another world model than {run} holds now; fit it again with "
            f"`orbitmodel depth {run} DATASET --imagined --overwrite`"
        )
    head = ImaginedDepthHead(model.config.latent_dim, config["imagined"]["hidden"])
    head.load_state_dict(load_weights(folder))
    return ImaginedDepth(head, float(model.depth_scale), timings)


def step_lines(result: dict) -> list[str]:
    """The eval's table: per step ahead, MAE and the share of near cells missed."""
    lines = [f"imagined depth on {result['eval_split']} windows (step = {result['frame_step']} frames):"]
    for s in result["steps"]:
        near = [b for b in s["bands"] if b["cells"] and (b["to_m"] or float("inf")) <= s["range_m"]]
        missed = sum(b["missed"] * b["cells"] for b in near) / max(1, sum(b["cells"] for b in near))
        lines.append(
            f"  step {s['step']:2d}: MAE {s['mae_m']:.2f} m, near cells missed {missed:.0%}, phantom {s['phantom'] or 0:.1%}"
        )
    return lines
