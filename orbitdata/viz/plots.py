"""Matplotlib pieces shared by `show` and the overview: figures in pixels, depth colours, time plots.

Matplotlib is the optional ``viz`` extra. It is imported on use, never through pyplot, and always
renders with the Agg canvas, so nothing here touches a display or global backend state. A figure
is rendered once into an RGB array; OpenCV then pastes camera frames and maps into named pixel
boxes, which keeps videos fast (one matplotlib draw per video, not per frame).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import cv2
import numpy as np

from orbitdata import schema as S
from orbitdata.load.episodes import Episode
from orbitdata.scenario.dynamics import NO_FAULT
from orbitdata.schema import DT

INSTALL_HINT = "pip install 'orbitdata[viz]'"
DPI = 100
DEPTH_CMAP = "turbo_r"  # near = red, far = blue; no return stays black
CURSOR = (255, 120, 40)  # RGB
SIGNAL = {"speed": "#50c8ff", "clearance": "#ffb347", "fuel": "#7ee07e", "danger": "#ff5050"}

# A dark theme that matches the OpenCV maps (background (18, 18, 24)).
THEME = {
    "figure.facecolor": "#121218",
    "axes.facecolor": "#1a1a22",
    "savefig.facecolor": "#121218",
    "axes.edgecolor": "#8a8a96",
    "axes.labelcolor": "#e6e6ee",
    "text.color": "#e6e6ee",
    "xtick.color": "#c0c0cc",
    "ytick.color": "#c0c0cc",
    "grid.color": "#3a3a48",
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.titleweight": "bold",
    "legend.frameon": False,
}


def require_matplotlib():
    """The matplotlib module, or an ImportError that says how to install it."""
    try:
        import matplotlib
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
    except ImportError as exc:
        raise ImportError(f"plotting needs matplotlib, which is not installed; {INSTALL_HINT}") from exc
    return matplotlib


@contextlib.contextmanager
def theme():
    mpl = require_matplotlib()
    with mpl.rc_context(THEME):
        yield mpl


def figure(width: int, height: int, scale: float = 1.0):
    """A Figure laid out in ``width`` x ``height`` pixels on an Agg canvas (call inside ``theme()``).

    It renders at ``scale`` times that size, fonts and lines included; ``add_axes`` keeps taking
    unscaled pixels.
    """
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width / DPI, height / DPI), dpi=DPI * scale)
    FigureCanvasAgg(fig)
    return fig


def render(fig) -> np.ndarray:
    """Draw the figure; (H, W, 3) uint8 RGB."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def add_axes(fig, x: int, y: int, w: int, h: int, **kwargs):
    """Axes whose plotting area is the (unscaled) pixel box (x, y, w, h), origin at the top left."""
    W, H = fig.get_size_inches() * DPI
    return fig.add_axes((x / W, 1 - (y + h) / H, w / W, h / H), **kwargs)


@dataclass(frozen=True)
class Box:
    """A pixel box of the rendered figure, origin at the top left, ``x1`` / ``y1`` exclusive."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def size(self) -> tuple[int, int]:
        return self.x1 - self.x0, self.y1 - self.y0  # (width, height)

    def paste(self, canvas: np.ndarray, img: np.ndarray) -> None:
        w, h = self.size
        assert img.shape[:2] == (h, w), f"panel {img.shape[:2]} does not fit box {(h, w)}"
        canvas[self.y0 : self.y1, self.x0 : self.x1] = img


def box_of(fig, ax) -> Box:
    """The pixel box of an axes' plotting area in the rendered figure."""
    b = ax.get_window_extent()
    H = int(round(fig.bbox.height))
    return Box(int(round(b.x0)), H - int(round(b.y1)), int(round(b.x1)), H - int(round(b.y0)))


def note(canvas: np.ndarray, box: Box, text: str, scale: float = 1.0) -> None:
    """A small grey caption in the top left corner of a pasted panel."""
    cv2.putText(
        canvas,
        text,
        (box.x0 + int(8 * scale), box.y0 + int(20 * scale)),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.45 * scale,
        (150, 150, 160),
        1,
        cv2.LINE_AA,
    )


NO_RETURN = "no return in range"


def fit(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Resize to (width, height): whole-pixel blocks when enlarging small frames, area otherwise."""
    w, h = size
    if img.shape[1] == w and img.shape[0] == h:
        return img
    interp = cv2.INTER_NEAREST if w >= 2 * img.shape[1] else cv2.INTER_AREA if w < img.shape[1] else cv2.INTER_LINEAR
    return cv2.resize(img, (w, h), interpolation=interp)


class DepthColours:
    """Metric depth -> RGB with a fixed range, so colours mean the same metres in every frame."""

    def __init__(self, depth_max: float):
        mpl = require_matplotlib()
        self.depth_max = float(depth_max)
        self.cmap = mpl.colormaps[DEPTH_CMAP]
        self.lut = (self.cmap(np.linspace(0, 1, 256))[:, :3] * 255).astype(np.uint8)  # (256, 3)

    @staticmethod
    def range_for(frames: list[np.ndarray]) -> float:
        """A round upper bound (metres) that covers 99% of the valid depth in ``frames``."""
        valid = np.concatenate([d[d > 0].ravel() for d in frames]) if frames else np.zeros(0)
        return float(max(1.0, np.ceil(np.percentile(valid, 99)))) if valid.size else 10.0

    def __call__(self, depth: np.ndarray) -> np.ndarray:
        k = np.clip(depth / self.depth_max * 255, 0, 255).astype(np.uint8)
        rgb = self.lut[k]
        rgb[depth <= 0] = 0
        return rgb

    def colorbar(self, fig, cax, label: str = "depth (m), black = no return") -> None:
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import Normalize

        bar = fig.colorbar(ScalarMappable(Normalize(0, self.depth_max), self.cmap), cax=cax)
        bar.set_label(label)


FAULT = "#ff50c8"  # the fault's onset, as on the maps (topdown.FAULT)
FAULT_GID = "fault-onset"  # the matplotlib gid of the onset lines, for whoever inspects a figure


def fault_label(fault: dict) -> str:
    """How the pictures name a thruster fault, e.g. ``fault: off thruster 3``."""
    return f"fault: {fault['kind']} thruster {fault['thruster']}"


def episode_fault(ep: Episode) -> dict | None:
    """A dynamic-tier episode's thruster fault (kind, thruster, level, onset_step), or None when it
    has none or its dataset records none (the static tier)."""
    fault = ep.meta.get(S.FAULT)
    return fault if fault is not None and fault["kind"] != NO_FAULT else None


def fault_onset(ep: Episode) -> int | None:
    """The frame at which the episode's thruster fault began, or None (no fault, or it was due
    only after the episode had ended)."""
    fault = episode_fault(ep)
    return fault["onset_step"] if fault is not None and fault["onset_step"] < len(ep) else None


def map_points(ep: Episode) -> np.ndarray:
    """(M, 3) metres, the points a map of the episode must show: its path and, on the dynamic
    tier, every piece of debris' track."""
    poses = ep.obstacle_poses
    if poses is None:
        return ep.positions
    return np.concatenate([ep.positions, poses[:, :, :3].reshape(-1, 3)])


def plot_signals(fig, axes: dict, ep: Episode, marks: list[int] = ()) -> None:
    """Speed, clearance, thrust and fuel against time on ``axes`` (keys of those names).

    ``marks``: frames to flag with numbered dotted lines (the contact sheet's key frames). A
    thruster fault's onset is a dashed line on every plot, labelled on the speed plot, with the
    faulty thruster's row marked on the thrust plot.
    """
    t = ep.times
    end = t[-1] if len(t) > 1 else DT
    ax = axes["speed"]
    ax.plot(t, ep.speed, color=SIGNAL["speed"], lw=1.5)
    ax.set_title("speed (m/s)")
    ax.set_ylim(0, max(0.5, float(ep.speed.max()) * 1.15))

    ax = axes["clearance"]
    ax.plot(t, ep.clearance, color=SIGNAL["clearance"], lw=1.5)
    ax.axhline(0, color=SIGNAL["danger"], lw=1, ls="--")
    k = int(np.argmin(ep.clearance))
    ax.plot([t[k]], [ep.clearance[k]], "o", color=SIGNAL["danger"] if ep.collision_at is not None else "white", ms=4)
    right = t[k] > 0.6 * t[-1]  # keep the label inside the axes
    ax.annotate(
        f"min {ep.clearance[k]:.2f} m",
        (t[k], ep.clearance[k]),
        xytext=(-4 if right else 4, 6),
        textcoords="offset points",
        ha="right" if right else "left",
        fontsize=8,
    )
    ax.set_title("clearance to nearest obstacle (m)")
    ax.set_ylim(min(-0.1, float(ep.clearance.min()) - 0.1), max(1.0, float(ep.clearance.max()) * 1.1))

    ax = axes["thrust"]
    img = ax.imshow(
        ep.actions.T,
        aspect="auto",
        cmap="magma",
        vmin=0,
        vmax=1,
        interpolation="nearest",
        extent=(-DT / 2, t[-1] + DT / 2, 7.5, -0.5),
    )
    ax.set_yticks(range(8))
    ax.tick_params(axis="y", labelsize=7)
    ax.set_title("thrust per thruster (0 to 1)")
    if "thrust_bar" in axes:
        fig.colorbar(img, cax=axes["thrust_bar"])

    ax = axes["fuel"]
    fuel = 100 * ep.fuel
    ax.plot(t, fuel, color=SIGNAL["fuel"], lw=1.5)
    ax.set_title("fuel left (%)")
    pad = max(0.5, 0.1 * float(fuel.max() - fuel.min()))
    ax.set_ylim(max(0.0, float(fuel.min()) - pad), min(100.0, float(fuel.max()) + pad) + 0.05 * pad)

    onset, fault = fault_onset(ep), episode_fault(ep)
    if onset is not None:
        for name in ("speed", "clearance", "thrust", "fuel"):
            axes[name].axvline(t[onset], color=FAULT, lw=1.2, ls="--", gid=FAULT_GID)
        right = t[onset] > 0.6 * t[-1]
        axes["speed"].text(
            t[onset],
            0.03,
            f"{fault_label(fault)} " if right else f" {fault_label(fault)}",
            transform=axes["speed"].get_xaxis_transform(),
            ha="right" if right else "left",
            va="bottom",
            fontsize=8,
            color=FAULT,
            gid=FAULT_GID,
        )
        axes["thrust"].plot([t[onset]], [fault["thruster"]], ">", color=FAULT, ms=6, gid=FAULT_GID)

    for name in ("speed", "clearance", "thrust", "fuel"):
        ax = axes[name]
        ax.set_xlim(-DT / 2, end + DT / 2)
        ax.set_xlabel("time (s)")
        if name != "thrust":
            ax.grid(True, lw=0.5)
        for n, f in enumerate(marks, 1):
            ax.axvline(t[f], color="white", lw=0.8, ls=":", alpha=0.8)
            last = f == len(t) - 1  # label the last mark on its left, inside the axes
            ax.text(
                t[f],
                0.98,
                f"{n} " if last else f" {n}",
                transform=ax.get_xaxis_transform(),
                ha="right" if last else "left",
                va="top",
                fontsize=8,
                color="white",
            )


@dataclass(frozen=True)
class TimeCursor:
    """Draws the current time as a vertical line across each time plot of a rendered figure."""

    boxes: tuple[Box, ...]
    lines: tuple[tuple[float, float], ...]  # per box: (px at t = 0, px per second)

    @classmethod
    def of(cls, fig, axes: list) -> "TimeCursor":
        lines = []
        for ax in axes:
            x0, _ = ax.transData.transform((0.0, 0.0))
            x1, _ = ax.transData.transform((1.0, 0.0))
            lines.append((float(x0), float(x1 - x0)))
        return cls(tuple(box_of(fig, ax) for ax in axes), tuple(lines))

    def draw(self, canvas: np.ndarray, t: float) -> None:
        for box, (off, slope) in zip(self.boxes, self.lines):
            x = int(round(off + slope * t))
            cv2.line(canvas, (x, box.y0), (x, box.y1 - 1), CURSOR, 2)


def setup_map_axes(ax, view, title: str) -> None:
    """Metre ticks on an axes whose plotting area will be covered by the OpenCV map ``view``.

    Limits put pixel centres on ``view``'s coordinates, so the ticks match what is pasted.
    """
    half = 0.5 / view.scale
    left, right, bottom, top = view.extent
    ax.set_xlim(left - half, right + half)
    ax.set_ylim(bottom - half, top + half)
    a, b = view.axis_names
    ax.set_xlabel(f"{a} (m)")
    ax.set_ylabel(f"{b} (m)", labelpad=1)
    ax.set_title(title)


def map_legend(
    fig,
    anchor: tuple[float, float],
    collision: bool,
    heading: bool = False,
    marks: bool = False,
    ncol: int = 6,
    debris: bool = False,
    fault: bool = False,
) -> None:
    """What the map symbols mean, in the maps' colours, centred at figure fraction ``anchor``;
    ``debris`` and ``fault`` add the dynamic tier's tracks and fault onset."""
    from matplotlib.lines import Line2D

    from orbitdata.viz import topdown as T

    def rgb(c):
        return tuple(x / 255 for x in c)

    items = [
        Line2D([], [], color=rgb(T.PATH), lw=2, label="path"),
        Line2D([], [], color=rgb(T.START), marker="+", ls="", ms=9, mew=2, label="start"),
        Line2D([], [], color=rgb(T.GOAL), marker="o", ls="", ms=9, mfc="none", mew=2, label="goal region"),
        Line2D([], [], color="#9a948c", marker="s", ls="", ms=9, label="obstacles (to scale)"),
    ]
    if heading:
        items.append(Line2D([], [], color=rgb(T.HEADING), lw=2, marker=">", ms=6, label="now, camera axis"))
    if marks:
        items.append(
            Line2D([], [], color=rgb(T.HEADING), marker="o", ls="-", lw=2, ms=6, label="key frames, camera axis")
        )
    if collision:
        items.append(Line2D([], [], color=rgb(T.HIT), marker="x", ls="", ms=9, mew=3, label="collision"))
    if debris:
        items.append(Line2D([], [], color=rgb(T.TRACK), marker="o", lw=1, ms=4, label="debris track from start"))
    if fault:
        items.append(
            Line2D([], [], color=rgb(T.FAULT), marker="D", ls="", ms=6, mfc="none", mew=2, label="fault onset")
        )
    fig.legend(
        handles=items, loc="center", bbox_to_anchor=anchor, ncol=ncol, fontsize=8, handlelength=1.6, columnspacing=1.2
    )
