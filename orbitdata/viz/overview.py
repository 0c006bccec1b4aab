"""``meta/overview.png``: what a dataset looks like at a glance, embedded in its card.

Sample frames for every (level, outcome) that occurs, the outcome rates per level and the
episode-length distribution. On the dynamic tier each sample also gets a top view of its flight:
the path, each piece of debris' track from its start and where the thruster fault began. The
writer draws it through :func:`orbitdata.viz.overview_figure`, which imports this module only
when matplotlib (the ``viz`` extra) is installed: importing it without matplotlib raises
ImportError, on purpose.

It stays fast on big datasets: one typical episode per (level, outcome), chosen
deterministically (the median length), and three of its frames, read row group by row group.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from PIL import Image

from orbitdata import schema as S
from orbitdata.codecs import decode_rgb
from orbitdata.load.rows import RowReader, read_rows
from orbitdata.scenario.dynamics import NO_FAULT
from orbitdata.state import POSITION
from orbitdata.viz import plots as P
from orbitdata.viz.topdown import PlaneMap
from orbitdata.write.parts import atomic_write

P.require_matplotlib()  # fail at import, so that `shard` skips the figure without the extra

OUTCOME_COLOURS = {
    "success": "#5fd35f",
    "collision": "#ff5a5a",
    "timeout": "#ffc04d",
    "out_of_fuel": "#b38cff",
    S.TUMBLING: "#4dd0e1",
}
THUMB_MIN, THUMB_MAX = 104, 200  # px
GRID_X = 110  # px, left edge of the sample grid
WIDTH = 1400
# A depth_low cell counts as filled below this share of the far plane: a cell with no return
# pools to the far plane itself, up to float32 rounding of the mean.
FAR_SHARE = 0.999


def sample_episodes(episodes: pa.Table) -> dict[tuple[str, str], dict]:
    """One typical episode per (level, outcome): the median length, ties to the lower index."""
    rows = episodes.select([S.EPISODE_INDEX, S.LEVEL, S.OUTCOME, S.LENGTH, S.DATA_FILE, S.ROW_START]).to_pylist()
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r[S.LEVEL], r[S.OUTCOME]), []).append(r)
    picks = {}
    for key, members in groups.items():
        members.sort(key=lambda r: (r[S.LENGTH], r[S.EPISODE_INDEX]))
        picks[key] = members[(len(members) - 1) // 2]
    return picks


def frames_to_show(out: Path, pick: dict, far: float) -> list[int]:
    """Start, the frame where obstacles fill most of the view, and just before the end.

    The fill is the share of the 16x16 ``depth_low`` cells nearer than the far plane ``far``
    (metres; a cell with no return pools to it), so no image is decoded to choose.
    """
    length = pick[S.LENGTH]
    if length < 3:
        return list(range(length))
    rows = read_rows(Path(out) / pick[S.DATA_FILE], pick[S.ROW_START], pick[S.ROW_START] + length, [S.DEPTH_LOW])
    low = rows.column(S.DEPTH_LOW).combine_chunks().values.to_numpy().reshape(length, -1)  # (L, 256) metres
    fill = (low < FAR_SHARE * far).mean(axis=1)  # (L,)
    end = max(2, int(round(0.9 * (length - 1))))
    first = max(1, min(length // 4, end - 1))  # not right after the start: that view barely differs
    middle = first + int(np.argmax(fill[first:end]))  # the first maximum: deterministic
    return sorted({0, middle, end})


def sample_frames(out: Path, picks: dict, far: float) -> dict[tuple[str, str], list[tuple[int, np.ndarray]]]:
    """(frame index, RGB) of each picked episode's frames to show, reading each data file once."""
    wanted: dict[str, list[tuple[tuple[str, str], int, int]]] = {}
    for key, r in picks.items():
        for t in frames_to_show(out, r, far):
            wanted.setdefault(r[S.DATA_FILE], []).append((key, t, r[S.ROW_START] + t))
    frames: dict = {key: [] for key in picks}
    for data_file, items in sorted(wanted.items()):
        cells = RowReader(Path(out) / data_file, [S.IMAGE]).cells([row for _, _, row in items], S.IMAGE)
        for (key, t, _), cell in zip(items, cells):
            frames[key].append((t, decode_rgb(cell["bytes"])))
    return frames


def is_dynamic(episodes: pa.Table) -> bool:
    """Whether the episodes are of the dynamic tier (they record a thruster fault)."""
    return S.FAULT in episodes.column_names


def sample_maps(out: Path, episodes: pa.Table, picks: dict) -> dict[tuple[str, str], dict]:
    """Per picked dynamic-tier episode: its scenario, path (L, 3), debris poses (L, N, 7) and fault."""
    from orbitdata.scenario.spec import Scenario

    picked = pa.array(sorted({p[S.EPISODE_INDEX] for p in picks.values()}), episodes.schema.field(S.EPISODE_INDEX).type)
    chosen = episodes.filter(pc.is_in(episodes.column(S.EPISODE_INDEX), value_set=picked))
    rows = {r[S.EPISODE_INDEX]: r for r in chosen.to_pylist()}
    maps = {}
    for key, pick in picks.items():
        row = rows[pick[S.EPISODE_INDEX]]
        length = row[S.LENGTH]
        steps = read_rows(
            Path(out) / row[S.DATA_FILE], row[S.ROW_START], row[S.ROW_START] + length, [S.STATE, S.OBSTACLE_POSES]
        )
        state = steps.column(S.STATE).combine_chunks().values.to_numpy().reshape(length, -1)
        poses = steps.column(S.OBSTACLE_POSES).combine_chunks().values.values.to_numpy()
        maps[key] = {
            "scenario": Scenario.from_dict(row),
            "positions": state[:, POSITION].astype(np.float64),
            "poses": poses.reshape(length, row[S.N_OBSTACLES], 7).astype(np.float64),
            "fault": row[S.FAULT],
            "collision": row[S.OUTCOME] == "collision",
        }
    return maps


def draw_map(flight: dict, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) uint8 top view of one picked flight: obstacles at their start, debris tracks, the
    path (a cross where it hit) and a diamond where the fault began."""
    positions, poses = flight["positions"], flight["poses"]
    view = PlaneMap(flight["scenario"], size, np.concatenate([positions, poses[:, :, :3].reshape(-1, 3)]))
    img = view.draw_tracks(view.background(), poses)
    view.draw_path(img, positions, positions[-1] if flight["collision"] else None)
    fault = flight["fault"]
    if fault["kind"] != NO_FAULT and fault["onset_step"] < len(positions):
        view.draw_fault(img, positions[fault["onset_step"]])
    return img


def fault_caption(fault: dict, length: int) -> str:
    """The fault of a picked episode, in the few words under its cell."""
    if fault["kind"] == NO_FAULT:
        return "no fault"
    when = f"{fault['onset_step'] * S.DT:.2f} s"
    return P.fault_label(fault) + (
        f" from {when}" if fault["onset_step"] < length else f" due at {when}, after the end"
    )


def tier_outcomes(episodes: pa.Table) -> tuple[str, ...]:
    """How the episodes' tier lets an episode end (``schema.outcomes``)."""
    return S.outcomes("dynamic" if is_dynamic(episodes) else "static")


def _levels_outcomes(episodes: pa.Table) -> tuple[list[str], list[str]]:
    levels = set(episodes.column(S.LEVEL).to_pylist())
    outcomes = set(episodes.column(S.OUTCOME).to_pylist())
    return [lv for lv in S.LEVELS if lv in levels], [o for o in tier_outcomes(episodes) if o in outcomes]


def render_overview(out: Path, episodes: pa.Table, far: float) -> np.ndarray:
    """The overview figure as an (H, W, 3) uint8 RGB array."""
    levels, outcomes = _levels_outcomes(episodes)
    picks = sample_episodes(episodes)
    frames = sample_frames(out, picks, far)
    maps = sample_maps(out, episodes, picks) if is_dynamic(episodes) else None
    panels = 3 if maps is None else 4  # three frames, and the top view on the dynamic tier
    n = len(outcomes)  # columns; thumbnails grow when there are few of them
    width = max(WIDTH, GRID_X + n * (panels * THUMB_MIN + 36) + 20)
    thumb = min(THUMB_MAX, (width - GRID_X - 20 - n * 36) // (panels * n))
    cell_w, row_h, grid_y = panels * thumb + 6 * (panels - 1), thumb + 44, 96
    pitch = cell_w + 24
    plots_y = grid_y + len(levels) * row_h + 40
    height = plots_y + 260
    rows = episodes.select([S.SPLIT, S.LEVEL, S.OUTCOME, S.LENGTH]).to_pylist()
    splits = {s: sum(1 for r in rows if r[S.SPLIT] == s) for s in S.SPLITS}
    size = frames[next(iter(frames))][0][1].shape[0] if frames else 0
    with P.theme():
        fig = P.figure(width, height)
        fig.text(
            0.5,
            1 - 24 / height,
            f"{len(rows)} episodes ({', '.join(f'{n} {s}' for s, n in splits.items() if n)})"
            f", {sum(r[S.LENGTH] for r in rows)} frames at {S.FPS} Hz, {size} px camera",
            ha="center",
            va="center",
            fontsize=14,
            weight="bold",
        )
        fig.text(
            0.5,
            1 - 48 / height,
            "a typical (median-length) episode per pilot level and outcome: its start, the frame where "
            "obstacles fill most of the view, and just before the end"
            + ("" if maps is None else "; its top view: path, debris tracks from their start (dot), fault onset"),
            ha="center",
            va="center",
            color="#b0b0bc",
        )
        boxes = []
        for j, outcome in enumerate(outcomes):
            x = GRID_X + j * pitch
            fig.text(
                (x + cell_w / 2) / width,
                1 - (grid_y - 14) / height,
                outcome.replace("_", " "),
                ha="center",
                va="center",
                fontsize=11,
                weight="bold",
                color=OUTCOME_COLOURS[outcome],
            )
        for i, level in enumerate(levels):
            y = grid_y + i * row_h
            fig.text(
                14 / width, 1 - (y + thumb / 2) / height, level, ha="left", va="center", fontsize=11, weight="bold"
            )
            for j, outcome in enumerate(outcomes):
                x = GRID_X + j * pitch
                pick = picks.get((level, outcome))
                if pick is None:
                    fig.text(
                        (x + cell_w / 2) / width,
                        1 - (y + thumb / 2) / height,
                        "no episodes",
                        ha="center",
                        va="center",
                        color="#70707c",
                    )
                    continue
                for k, (t, rgb) in enumerate(frames[(level, outcome)]):
                    ax = P.add_axes(fig, x + k * (thumb + 6), y, thumb, thumb)
                    ax.set_axis_off()
                    boxes.append((ax, rgb))
                caption = f"episode {pick[S.EPISODE_INDEX]} ({pick[S.LENGTH]} frames): frames " + ", ".join(
                    str(t) for t, _ in frames[(level, outcome)]
                )
                if maps is not None:
                    ax = P.add_axes(fig, x + 3 * (thumb + 6), y, thumb, thumb)
                    ax.set_axis_off()
                    boxes.append((ax, maps[(level, outcome)]))
                    caption += "; " + fault_caption(maps[(level, outcome)]["fault"], pick[S.LENGTH])
                fig.text(
                    (x + cell_w / 2) / width,
                    1 - (y + thumb + 14) / height,
                    caption,
                    ha="center",
                    va="center",
                    fontsize=8,
                    color="#b0b0bc",
                )
        split = int(0.55 * width)
        _rates(fig, P.add_axes(fig, 110, plots_y, split - 180, 180), rows, levels, tier_outcomes(episodes))
        _lengths(fig, P.add_axes(fig, split + 40, plots_y, width - split - 80, 180), rows, levels)
        image = P.render(fig)
        for ax, panel in boxes:
            box = P.box_of(fig, ax)
            box.paste(image, draw_map(panel, box.size) if isinstance(panel, dict) else P.fit(panel, box.size))
    return image


def _rates(fig, ax, rows: list[dict], levels: list[str], outcomes: tuple[str, ...]) -> None:
    """Stacked horizontal bars: the share of each outcome per level, with counts."""
    for i, level in enumerate(levels):
        mine = [r for r in rows if r[S.LEVEL] == level]
        left = 0.0
        for outcome in outcomes:
            n = sum(1 for r in mine if r[S.OUTCOME] == outcome)
            share = n / len(mine)
            if n:
                ax.barh(i, share, left=left, color=OUTCOME_COLOURS[outcome], height=0.6)
                if share >= 0.08:
                    ax.text(
                        left + share / 2,
                        i,
                        f"{100 * share:.0f}%",
                        ha="center",
                        va="center",
                        color="#121218",
                        fontsize=9,
                        weight="bold",
                    )
            left += share
        ax.text(1.01, i, f"n = {len(mine)}", va="center", fontsize=9)
    ax.set_yticks(range(len(levels)), levels)
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.set_xticks(np.linspace(0, 1, 6), [f"{x:.0%}" for x in np.linspace(0, 1, 6)])
    ax.set_title("outcome rates per level (all splits)")
    from matplotlib.patches import Patch

    ax.legend(
        handles=[Patch(color=OUTCOME_COLOURS[o], label=o.replace("_", " ")) for o in outcomes],
        loc="upper center",
        bbox_to_anchor=(0.5, -0.14),
        ncol=len(outcomes),
        fontsize=9,
    )


def _lengths(fig, ax, rows: list[dict], levels: list[str]) -> None:
    """Episode-length histograms per level."""
    colours = {"expert": "#50c8ff", "risky": "#ff8a50", "exploratory": "#c8a0ff"}
    longest = max(r[S.LENGTH] for r in rows)
    bins = np.linspace(0, max(10, longest), 31)
    for level in levels:
        lengths = [r[S.LENGTH] for r in rows if r[S.LEVEL] == level]
        ax.hist(lengths, bins=bins, histtype="step", lw=1.8, color=colours.get(level), label=level)
    ax.set_title("episode length")
    ax.set_xlabel("frames")
    ax.set_ylabel("episodes")
    ax.legend(fontsize=9)
    ax.grid(True, lw=0.5)
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(integer=True))


def write_overview(out: Path, episodes: pa.Table, far: float) -> Path:
    """Render the overview of the dataset in ``out`` to ``meta/overview.png``; returns the path."""
    if episodes.num_rows == 0:
        raise ValueError(f"{out} holds no episodes; there is nothing to draw an overview of")
    image = render_overview(Path(out), episodes, far)
    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG", optimize=True)
    path = Path(out) / S.OVERVIEW_PATH
    atomic_write(path, buf.getvalue())
    return path
