"""``orbitmodel eval rollout``: the paper's Figures 3 and 4 on held-out test windows.

* Latent rollout error versus horizon h = 1..H: from the 8 encoded context frames, imagine H
  latents with the recorded actions and compare them with the encodings of the real frames.
  MSE is averaged over latent dimensions; NMSE divides it by the latents' mean per-dimension
  variance over the test frames, so 1.0 is the error of guessing the average latent.
* Baselines on the same windows: persistence (z_{t+h} = z_t) and the same rollout with the
  planned actions of another window (the context's own actions are kept), which shows whether
  the model uses the actions at all.
* Depth: the depth head on every frame of the windows against ``observation.depth_low``, as MAE
  in metres, beside predicting the train split's per-cell mean (``meta/stats.json``); and by
  band of true depth (0-2, 2-5, 5-10 m and beyond), the MAE and the share of cells the head puts
  at or beyond the planner's 10 m range (cells the planner then does not plan around: *missed*),
  plus the share of far cells it brings inside that range (*phantom* obstacles).
* Collapse: the per-dimension std of z and its effective rank, over ``frames`` test frames drawn
  at random from the whole split (their variance also normalises the NMSE).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from orbitdata import schema as S
from orbitdata.load import load_windows
from orbitdata.load.index import NoWindow
from orbitmodel.data import load_model_windows, read_dataset_meta, split_selection
from orbitmodel.model.world_model import WorldModel, effective_rank
from orbitmodel.plan.config import MAX_RANGE
from orbitmodel.plan.depth_bands import DEPTH_BANDS_M, band_lines, depth_by_band
from orbitmodel.runs import RunError, check_image_size

COLUMNS = (S.IMAGE, S.STATE, S.ACTION, S.DEPTH_LOW)


@dataclass(frozen=True)
class RolloutEvalConfig:
    context: int = 8
    horizon: int = 50
    windows: int = 100
    seed: int = 0
    batch: int = 16
    check_h: int = 12  # where the shuffled-action ratio is reported
    frames: int = 4000  # independent frames for the latent variance and the collapse diagnostics
    split: str = "test"  # or "val": the run's validation episodes of the train split (orbitmodel.data)
    depth_bands: tuple[float, ...] = DEPTH_BANDS_M
    depth_range: float = MAX_RANGE  # metres: cells beyond it are no obstacle to the planner


def derangement(n: int, seed: int) -> np.ndarray:
    """A permutation of range(n) without fixed points (n >= 2), from ``seed``.

    Random permutations are redrawn until one has no fixed point (the committed rollout
    evaluations were drawn this way); if the redraws repeat themselves (small n), a random cycle is
    taken instead.
    """
    shuffle, tried = np.random.default_rng(seed + 1).permutation(n), set()
    while n > 1 and np.any(shuffle == np.arange(n)):
        redraw = int(shuffle[0]) + seed + 2
        if redraw in tried:  # the redraws cycle: take the order of a random permutation as one cycle
            order = np.random.default_rng(seed + 1).permutation(n)
            shuffle = np.empty(n, dtype=np.int64)
            shuffle[order] = np.roll(order, -1)
            break
        tried.add(redraw)
        shuffle = np.random.default_rng(redraw).permutation(n)
    return shuffle


def _select(n_total: int, n: int, seed: int, where: str) -> np.ndarray:
    if n_total < n:
        raise RunError(f"{where} has {n_total} windows, fewer than the {n} asked; pass --windows {n_total} or less")
    return np.sort(np.random.default_rng(seed).choice(n_total, size=n, replace=False))


@torch.no_grad()
def evaluate_rollout(run: str | Path, dataset: str, cfg: RolloutEvalConfig = RolloutEvalConfig()) -> dict:
    """Every figure of the rollout evaluation, as one JSON-able dict (curves per window included)."""
    torch.set_grad_enabled(False)
    model = WorldModel.from_pretrained(run)
    check_image_size(read_dataset_meta(dataset), model.config.image_size, f"the world model of {run}")
    stats_mean = _depth_mean(dataset)
    step = model.config.frame_step  # context and horizon count the model's steps of `step` frames
    split, episodes = split_selection(cfg.split, model.run.validation)
    try:
        windows = load_model_windows(
            dataset,
            step,
            split=split,
            episodes=episodes,
            context=cfg.context,
            horizon=cfg.horizon,
            columns=list(COLUMNS),
        )
    except NoWindow as err:  # say it in the flag's steps, with the largest horizon that fits
        most = err.longest // step - cfg.context
        raise ValueError(
            f"--horizon {cfg.horizon}: {cfg.context} context and {cfg.horizon} horizon steps of {step} "
            f"frame{'s' * (step > 1)} are longer than every episode of the {cfg.split} split of {dataset} "
            f"(longest: {err.longest} frames); "
            + (f"give --horizon {most} or less" if most >= 1 else "no horizon fits this split")
        ) from None
    chosen = _select(
        len(windows),
        cfg.windows,
        cfg.seed,
        f"the {cfg.split} split of {dataset} (windows of "
        f"{cfg.context}+{cfg.horizon} steps of {step} frame{'s' * (step > 1)})",
    )
    shuffle = derangement(len(chosen), cfg.seed)  # each window rolls out another window's actions
    m, n = cfg.context, cfg.horizon
    z_true, z_pred, z_shuf, depth_err, depth_base, episodes = [], [], [], [], [], []
    depth_pairs: list[tuple[torch.Tensor, torch.Tensor]] = []
    all_actions = torch.stack([windows[int(i)][S.ACTION] for i in chosen])  # (N, T, 8)
    for start in range(0, len(chosen), cfg.batch):
        idx = chosen[start : start + cfg.batch]
        batch = [windows[int(i)] for i in idx]
        images = torch.stack([b[S.IMAGE] for b in batch])  # (b, T, 3, H, W) uint8
        states = torch.stack([b[S.STATE] for b in batch])  # (b, T, 16)
        actions = all_actions[start : start + len(idx)]
        depth = torch.stack([b[S.DEPTH_LOW] for b in batch])  # (b, T, 16, 16) m
        z = model.encode(images, states)  # (b, T, D)
        z_true.append(z)
        z_pred.append(model.rollout(z[:, :m], actions[:, : m + n - 1]))
        other = all_actions[shuffle[start : start + len(idx)]]
        mixed = torch.cat([actions[:, : m - 1], other[:, m - 1 : m + n - 1]], dim=1)
        z_shuf.append(model.rollout(z[:, :m], mixed))
        pred_depth = model.predict_depth(images)
        depth_err.append((pred_depth - depth).abs().flatten(1).mean(1))
        depth_base.append((stats_mean - depth).abs().flatten(1).mean(1))
        depth_pairs.append((pred_depth.flatten(), depth.flatten()))
        episodes += [int(b[S.EPISODE_INDEX][0]) for b in batch]
    z_true, z_pred, z_shuf = torch.cat(z_true), torch.cat(z_pred), torch.cat(z_shuf)  # (N, T, D), (N, n, D)
    future = z_true[:, m:]  # (N, n, D)
    flat = _frame_latents(model, dataset, cfg, split, episodes)  # (F, D) independent frames of the split
    var = float(flat.var(0).mean())
    mse = ((z_pred - future) ** 2).mean(-1)  # (N, n)
    persistence = ((z_true[:, m - 1 : m] - future) ** 2).mean(-1)
    shuffled = ((z_shuf - future) ** 2).mean(-1)
    curve = lambda x: x.mean(0).tolist()  # noqa: E731
    h = cfg.check_h
    std = flat.std(0)
    result = {
        "run": str(run),
        "dataset": str(dataset),
        "config": asdict(cfg),
        "frame_step": step,
        "episodes": episodes,
        "latent_dim": flat.shape[1],
        "latent_variance": var,
        "latent_frames": len(flat),
        "horizons": list(range(1, n + 1)),
        "mse": curve(mse),
        "nmse": curve(mse / var),
        "persistence_nmse": curve(persistence / var),
        "shuffled_nmse": curve(shuffled / var),
        "nmse_per_window": (mse / var).tolist(),
        "depth_mae_m": float(torch.cat(depth_err).mean()),
        "depth_mean_baseline_mae_m": float(torch.cat(depth_base).mean()),
        "depth_by_band": depth_by_band(
            torch.cat([p for p, _ in depth_pairs]),
            torch.cat([t for _, t in depth_pairs]),
            cfg.depth_bands,
            cfg.depth_range,
        ),
        "z_std": std.tolist(),
        "z_std_min": float(std.min()),
        "z_std_median": float(std.median()),
        "effective_rank": effective_rank(flat),
    }
    nmse, pers = np.array(result["nmse"]), np.array(result["persistence_nmse"])
    result["checks"] = {
        "nmse_below_persistence_at_every_h": bool(np.all(nmse < pers)),
        f"shuffled_over_recorded_nmse_at_h{h}": float(result["shuffled_nmse"][h - 1] / max(nmse[h - 1], 1e-12)),
        "depth_mae_reduction_vs_mean": 1 - result["depth_mae_m"] / max(result["depth_mean_baseline_mae_m"], 1e-12),
        "effective_rank_over_dim": result["effective_rank"] / result["latent_dim"],
    }
    result["depth_examples"] = _depth_examples(model, windows, chosen, cfg)
    return result


def _frame_latents(model: WorldModel, dataset: str, cfg: RolloutEvalConfig, split: str, episodes) -> torch.Tensor:
    """z of ``cfg.frames`` test frames drawn at random over the whole split (F, D). The frames of a
    window are nearly alike, so the windows alone would understate the latents' spread."""
    frames = load_windows(dataset, split=split, context=1, horizon=0, columns=[S.IMAGE, S.STATE], episodes=episodes)
    idx = np.sort(np.random.default_rng(cfg.seed + 3).choice(len(frames), min(cfg.frames, len(frames)), replace=False))
    out = []
    for start in range(0, len(idx), 256):
        batch = [frames[int(i)] for i in idx[start : start + 256]]
        out.append(
            model.encode(torch.stack([b[S.IMAGE] for b in batch]), torch.stack([b[S.STATE] for b in batch]))[:, 0]
        )
    return torch.cat(out)


def _depth_mean(dataset: str) -> torch.Tensor:
    from orbitdata.load import read_meta

    _, stats = read_meta(dataset)
    return torch.tensor(stats[S.DEPTH_LOW]["mean"], dtype=torch.float32).view(S.DEPTH_LOW_SIDE, S.DEPTH_LOW_SIDE)


def _depth_examples(model: WorldModel, windows, chosen: np.ndarray, cfg: RolloutEvalConfig, k: int = 6) -> list:
    """k test frames (image, true and predicted depth) for Figure 4: the ones with the nearest obstacles."""
    out = []
    for i in chosen[:: max(1, len(chosen) // k)][:k]:
        w = windows[int(i)]
        t = int(torch.argmin(w[S.DEPTH_LOW].flatten(1).min(1).values))  # the frame with the nearest return
        pred = model.predict_depth(w[S.IMAGE][t][None, None])[0, 0]
        out.append(
            {
                "episode": int(w[S.EPISODE_INDEX][0]),
                "frame": int(w[S.FRAME_INDEX][t]),
                "image": w[S.IMAGE][t].permute(1, 2, 0).numpy().tolist(),
                "true": w[S.DEPTH_LOW][t].numpy().tolist(),
                "pred": pred.numpy().tolist(),
            }
        )
    return out


def write_rollout_report(result: dict, out: Path) -> list[Path]:
    """rollout.json (without the example pixels), rollout.png (Figure 3), depth.png (Figure 4)."""
    from orbitmodel.evaluate.plots import plot_depth, plot_rollout

    out.mkdir(parents=True, exist_ok=True)
    examples = result.pop("depth_examples", [])
    paths = [out / "rollout.json", out / "rollout.png", out / "depth.png"]
    paths[0].write_text(json.dumps(result, indent=1) + "\n")
    plot_rollout(result, paths[1])
    plot_depth(examples, result, paths[2])
    return paths


def summary_lines(result: dict) -> list[str]:
    c = result["checks"]
    h = result["config"]["check_h"]
    rows = [
        f"latent rollout on {result['config']['windows']} {result['config'].get('split', 'test')} windows "
        f"(context {result['config']['context']}, horizon {result['config']['horizon']}"
        + (f"; h counts steps of {result['frame_step']} frames" if result.get("frame_step", 1) > 1 else "")
        + "):",
        "   h   NMSE   persistence   shuffled actions",
    ]
    for k in (1, 5, 12, 25, 50):
        if k <= len(result["nmse"]):
            rows.append(
                f"  {k:2d}  {result['nmse'][k - 1]:.4f}   {result['persistence_nmse'][k - 1]:.4f}       "
                f"{result['shuffled_nmse'][k - 1]:.4f}"
            )
    rows += [
        f"NMSE below persistence at every h: {c['nmse_below_persistence_at_every_h']}",
        f"shuffled / recorded NMSE at h={h}: {c[f'shuffled_over_recorded_nmse_at_h{h}']:.2f}",
        f"depth MAE {result['depth_mae_m']:.3f} m vs mean baseline {result['depth_mean_baseline_mae_m']:.3f} m "
        f"({100 * c['depth_mae_reduction_vs_mean']:.0f} % lower)",
        *band_lines(result.get("depth_by_band")),
        f"effective rank {result['effective_rank']:.1f} of {result['latent_dim']} dims over {result['latent_frames']} frames; "
        f"z std min {result['z_std_min']:.3f}, median {result['z_std_median']:.3f}",
    ]
    return rows
