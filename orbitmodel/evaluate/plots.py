"""Figures of the evaluations (matplotlib, the ``viz`` extra, imported on use)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from orbitmodel.extras import pyplot


def plot_rollout(result: dict, path: Path) -> None:
    """Figure 3: NMSE of the latent rollout vs horizon, one thin line per window, the mean bold,
    with persistence and shuffled actions beside it."""
    plt = pyplot()
    h = np.array(result["horizons"])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, log in zip(axes, (False, True)):
        for curve in result["nmse_per_window"]:
            ax.plot(h, curve, color="tab:blue", lw=0.5, alpha=0.25)
        ax.plot(h, result["nmse"], color="tab:blue", lw=2.5, label="world model (recorded actions)")
        ax.plot(
            h, result["shuffled_nmse"], color="tab:red", lw=2, ls="--", label="world model, another window's actions"
        )
        ax.plot(h, result["persistence_nmse"], color="k", lw=2, ls=":", label="persistence z(t+h) = z(t)")
        ax.set_xlabel("horizon h (steps of 0.04 s)")
        ax.set_ylabel("latent NMSE")
        if log:
            ax.set_yscale("log")
    axes[0].set_ylim(0, max(1.5, 1.1 * max(result["persistence_nmse"])))
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"latent rollout error, {len(result['nmse_per_window'])} test windows")
    axes[1].set_title("same, log scale")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_depth(examples: list, result: dict, path: Path) -> None:
    """Figure 4: test frames, their 16x16 depth and the depth head's prediction (metres)."""
    plt = pyplot()
    if not examples:
        return
    fig, axes = plt.subplots(3, len(examples), figsize=(2.2 * len(examples), 6.6), squeeze=False)
    vmax = 10.0
    for j, ex in enumerate(examples):
        axes[0, j].imshow(np.asarray(ex["image"], dtype=np.uint8))
        axes[0, j].set_title(f"ep {ex['episode']} f {ex['frame']}", fontsize=8)
        im = axes[1, j].imshow(np.asarray(ex["true"]), vmin=0, vmax=vmax, cmap="viridis_r")
        axes[2, j].imshow(np.asarray(ex["pred"]), vmin=0, vmax=vmax, cmap="viridis_r")
        for i in range(3):
            axes[i, j].set_xticks([])
            axes[i, j].set_yticks([])
    axes[0, 0].set_ylabel("RGB")
    axes[1, 0].set_ylabel("depth_low (true)")
    axes[2, 0].set_ylabel("depth head")
    fig.colorbar(im, ax=axes[1:, :].ravel().tolist(), shrink=0.8, label="metres (clipped at 10)")
    fig.suptitle(
        f"depth MAE {result['depth_mae_m']:.2f} m vs predict-the-mean {result['depth_mean_baseline_mae_m']:.2f} m"
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)
