"""Figure 5: predicted versus true states over one window, and 3-D views of a collision-free
window and of one that ends in a collision (matplotlib, the ``viz`` extra, imported on use)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from orbitdata import schema as S
from orbitdata.scenario.spec import Scenario
from orbitdata.state import STATE_NAMES
from orbitmodel.extras import pyplot
from orbitmodel.kinematics import P

FIG_STATES, FIG_3D = "probe_fig5_states.png", "probe_fig5_3d.png"
STYLE = {
    "truth": dict(color="black", lw=1.8, label="true"),
    "probe": dict(color="tab:red", lw=1.4, label="ours (probe on imagined latents)"),
    "state_mlp": dict(color="tab:blue", lw=1.1, ls="--", label="state-only MLP"),
    "constant_velocity": dict(color="tab:gray", lw=1.1, ls=":", label="constant velocity"),
}
NEAR = 2.0  # metres: obstacles drawn when within this of the window's path


def plot_states(context_states: np.ndarray, states: dict[str, np.ndarray], dt: float, path: Path, title: str) -> None:
    """4 x 4 panels, one per state entry: context (m, 16) then each row's (n, 16) over time."""
    plt = pyplot()
    m, n = len(context_states), len(states["truth"])
    t_ctx = (np.arange(m) - (m - 1)) * dt  # seconds; 0 = last context frame
    t = np.arange(1, n + 1) * dt
    fig, axes = plt.subplots(4, 4, figsize=(15, 10), sharex=True)
    for i, ax in enumerate(axes.flat):
        ax.plot(t_ctx, context_states[:, i], color="black", lw=1.0, alpha=0.4)
        for row, s in states.items():
            ax.plot(t, s[:, i], **STYLE[row])
        ax.axvline(0, color="gray", lw=0.5)
        ax.set_title(STATE_NAMES[i], fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("time after the last context frame (s)")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, frameon=False)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _sphere(ax, center, radius: float) -> None:
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
    ax.plot_wireframe(
        center[0] + radius * np.cos(u) * np.sin(v),
        center[1] + radius * np.sin(u) * np.sin(v),
        center[2] + radius * np.cos(v),
        color="tab:orange",
        lw=0.4,
        alpha=0.6,
    )


def plot_3d(panels: list[dict], path: Path) -> None:
    """One 3-D panel per window: {"title", "context" (m, 3), "paths": {row: (n, 3)}, "obstacles"}."""
    plt = pyplot()
    fig = plt.figure(figsize=(7 * len(panels), 6.5))
    for k, panel in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        ctx = panel["context"]
        ax.plot(*ctx.T, color="black", lw=1.0, alpha=0.4)
        ax.scatter(*ctx[-1], color="green", s=30, label="last context frame")
        points = [ctx, *panel["paths"].values()]
        for row, xyz in panel["paths"].items():
            ax.plot(*xyz.T, **STYLE[row])
        for center, radius in panel["obstacles"]:
            _sphere(ax, center, radius)
            points.append(np.stack([center - radius, center + radius]))
        pts = np.concatenate(points)
        mid, half = (pts.max(0) + pts.min(0)) / 2, (pts.max(0) - pts.min(0)).max() / 2 + 0.1
        ax.set_xlim(mid[0] - half, mid[0] + half)
        ax.set_ylim(mid[1] - half, mid[1] + half)
        ax.set_zlim(mid[2] - half, mid[2] + half)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.set_title(panel["title"], fontsize=10)
        if k == 0:
            ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _obstacles(dataset: str, episode: int, path_xyz: np.ndarray, split: str) -> list[tuple[np.ndarray, float]]:
    from orbitdata.load.tables import load_episode_table

    table = load_episode_table(dataset, split, {})
    row = next(r for r in table.to_pylist() if r[S.EPISODE_INDEX] == episode)
    near = []
    for ob in Scenario.from_dict(row).obstacles:
        center, radius = np.asarray(ob.center, dtype=float), ob.bounding_radius
        if np.linalg.norm(path_xyz - center, axis=1).min() < radius + NEAR:
            near.append((center, radius))
    return near


def _panel(window: dict, j: int, context: int, dataset: str, title: str, split: str) -> dict:
    states = {k: v[j].numpy() for k, v in window["states"].items()}
    ctx = window["batch"][S.STATE][j, :context, P].numpy()
    episode = int(window["batch"][S.EPISODE_INDEX][j, 0])
    first = int(window["batch"][S.FRAME_INDEX][j, 0])
    path_xyz = np.concatenate([ctx, states["truth"][:, P]])
    return {
        "title": f"{title}: episode {episode}, frames {first}..{first + len(path_xyz) - 1}",
        "context": ctx,
        "paths": {row: s[:, P] for row, s in states.items()},
        "obstacles": _obstacles(dataset, episode, path_xyz, split),
    }


def figure5(
    first: dict, crash: dict | None, dataset: str, context: int, dt: float, out: Path, split: str = "test"
) -> list[str]:
    """Write Figure 5 into ``out``: the states of the first evaluated window, and 3-D views of it
    and of the collision window (when the test split has one). Returns the files written."""
    states = {k: v[0].numpy() for k, v in first["states"].items()}
    episode = int(first["batch"][S.EPISODE_INDEX][0, 0])
    n = len(states["truth"])
    plot_states(
        first["batch"][S.STATE][0, :context].numpy(),
        states,
        dt,
        out / FIG_STATES,
        f"Predicted vs true state over {n} steps ({n * dt:.1f} s), {split} episode {episode}",
    )
    panels = [_panel(first, 0, context, dataset, "collision-free", split)]
    if crash is not None:
        panels.append(_panel(crash, 0, context, dataset, "ends in a collision", split))
    plot_3d(panels, out / FIG_3D)
    return [str(out / FIG_STATES), str(out / FIG_3D)]
