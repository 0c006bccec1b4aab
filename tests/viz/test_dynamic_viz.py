"""Pictures of the dynamic tier: `show` and the overview draw each piece of debris' track and mark
where and when the thruster fault began."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from orbitdata import schema as S
from orbitdata.load.episodes import Episode, load_episode, read_episodes
from orbitdata.viz import plots as P
from orbitdata.viz.contact_sheet import ContactSheet
from orbitdata.viz.overview import sample_episodes
from orbitdata.viz.show import EpisodeVideo
from orbitdata.viz.topdown import FAULT, TRACK

PLOTS = ("speed", "clearance", "thrust", "fuel")
PLOTS_HEIGHT = 260  # px at the bottom of the overview: outcome rates and lengths


@pytest.fixture(scope="module")
def dynamic_dataset(dynamic_master) -> Path:
    """The session's dynamic-tier dataset (do not modify it)."""
    return dynamic_master


def _episodes(root: Path) -> list[dict]:
    return read_episodes(root, [S.EPISODE_INDEX, S.LENGTH, S.N_OBSTACLES, S.FAULT]).to_pylist()


@pytest.fixture(scope="module")
def faulty(dynamic_dataset) -> Episode:
    """An episode whose fault begins mid-flight, with several pieces of debris."""
    rows = [r for r in _episodes(dynamic_dataset) if r[S.FAULT]["kind"] != "none"]
    rows = [r for r in rows if 0 < r[S.FAULT]["onset_step"] < r[S.LENGTH] - 5 and r[S.N_OBSTACLES] > 1]
    assert rows, "the tiny dynamic dataset has no episode whose fault begins mid-flight"
    return load_episode(dynamic_dataset, rows[0][S.EPISODE_INDEX])


@pytest.fixture(scope="module")
def sparse(dynamic_dataset) -> Episode:
    """Of the episodes whose every piece of debris travels at least 0.8 m, the one with the fewest
    pieces: its tracks are long, and a shifted track cannot land on another."""
    episodes = [load_episode(dynamic_dataset, r[S.EPISODE_INDEX]) for r in _episodes(dynamic_dataset)]
    moving = [ep for ep in episodes if (_travel(ep) >= 0.8).all()]
    assert moving, "no episode of the tiny dynamic dataset has debris that travels 0.8 m"
    return min(moving, key=lambda ep: (ep.meta[S.N_OBSTACLES], ep.index))


def _travel(ep: Episode) -> np.ndarray:
    poses = ep.obstacle_poses
    return np.linalg.norm(poses[-1, :, :3] - poses[0, :, :3], axis=1)  # (N,) metres


def _share(img: np.ndarray, pixels: np.ndarray, colour, tol: int = 60) -> float:
    """Share of ``pixels`` (N, 2) (column, row) drawn in ``colour``."""
    pixels = np.unique(pixels, axis=0)
    colours = img[pixels[:, 1], pixels[:, 0]].astype(int)
    return float((np.abs(colours - colour).max(axis=1) <= tol).mean())


def _count(img: np.ndarray, colour, tol: int = 40) -> int:
    return int((np.abs(img.astype(int) - colour).max(axis=-1) <= tol).sum())


def test_show_draws_one_track_per_piece_of_debris_where_its_record_says(faulty):
    video = EpisodeVideo(faulty)
    poses = faulty.obstacle_poses
    assert poses.shape == (len(faulty), faulty.meta[S.N_OBSTACLES], 7)
    frame = video.frame(0)
    for view in ("top", "side"):
        for piece in range(poses.shape[1]):
            pixels = video.track_pixels(view, piece)
            box = video.boxes[view]
            assert (pixels[:, 0] >= box.x0).all() and (pixels[:, 0] < box.x1).all()
            assert _share(frame, pixels, TRACK) > 0.8, (view, piece)


def test_a_track_is_drawn_where_the_piece_went_and_nowhere_else(sparse):
    video = EpisodeVideo(sparse)
    panel = video.map_background["top"]  # the map under every frame: tracks, no outlines of now
    box = video.boxes["top"]
    for piece in range(sparse.meta[S.N_OBSTACLES]):
        pixels = video.track_pixels("top", piece) - [box.x0, box.y0]
        assert _share(panel, pixels, TRACK) > 0.8
        along = (pixels[-1] - pixels[0]) / np.linalg.norm(pixels[-1] - pixels[0])
        across = np.rint(9 * np.array([-along[1], along[0]])).astype(int)  # 9 px to the side
        assert _share(panel, pixels[4:] + across, TRACK) < 0.5


def test_show_marks_the_fault_onset_on_every_time_plot(faulty):
    onset = faulty.meta[S.FAULT]["onset_step"]
    video = EpisodeVideo(faulty)

    def marked_rows(box, x0, px_per_s, t) -> float:
        """Share of the plot's rows with the onset's colour within a pixel of time ``t``."""
        x = int(round(x0 + px_per_s * t))
        strip = video.background[box.y0 : box.y1, x - 1 : x + 2].astype(int)  # (H, 3, 3)
        return float((np.abs(strip - FAULT_RGB).max(axis=-1) <= 60).any(axis=1).mean())

    for box, (x0, px_per_s) in zip(video.cursor.boxes, video.cursor.lines):
        assert marked_rows(box, x0, px_per_s, faulty.times[onset]) > 0.4  # dashed, the plot's height
        assert marked_rows(box, x0, px_per_s, faulty.times[onset // 2]) == 0


def test_the_onset_lines_and_label_name_the_fault(faulty):
    fault = faulty.meta[S.FAULT]
    with P.theme():
        fig = P.figure(1200, 300)
        axes = {name: P.add_axes(fig, 60 + 280 * i, 40, 220, 220) for i, name in enumerate(PLOTS)}
        P.plot_signals(fig, axes, faulty)
        for name in PLOTS:
            lines = [a for a in axes[name].get_lines() if a.get_gid() == P.FAULT_GID]
            assert [float(line.get_xdata()[0]) for line in lines][:1] == [faulty.times[fault["onset_step"]]]
        labels = [t.get_text().strip() for t in axes["speed"].texts if t.get_gid() == P.FAULT_GID]
    assert labels == [f"fault: {fault['kind']} thruster {fault['thruster']}"]


def test_show_marks_where_the_fault_began_on_the_maps(faulty):
    onset = faulty.meta[S.FAULT]["onset_step"]
    video = EpisodeVideo(faulty)
    u, v = video.top.px(faulty.positions[onset]) + np.array([video.boxes["top"].x0, video.boxes["top"].y0])
    near = (slice(v - 7, v + 8), slice(u - 7, u + 8))
    assert _count(video.frame(onset)[near], FAULT) > 4
    assert _count(video.frame(onset - 1)[near], FAULT) == 0  # not before it began


def test_the_contact_sheet_draws_the_tracks_and_names_the_fault(faulty):
    sheet = ContactSheet(faulty)
    for piece in range(faulty.meta[S.N_OBSTACLES]):
        assert _share(sheet.image, sheet.track_pixels("top", piece), TRACK) > 0.7, piece
    fault = faulty.meta[S.FAULT]
    assert f"fault: {fault['kind']} thruster {fault['thruster']} from " in sheet._subtitle()


def test_the_overview_draws_tracks_and_fault_onsets(dynamic_dataset):
    with Image.open(dynamic_dataset / S.OVERVIEW_PATH) as im:
        grid = np.asarray(im.convert("RGB"))[:-PLOTS_HEIGHT]  # the samples, without the plots' legends
    assert _count(grid, TRACK, tol=20) > 50
    table = read_episodes(dynamic_dataset)
    rows = {r[S.EPISODE_INDEX]: r for r in _episodes(dynamic_dataset)}
    picked = [rows[p[S.EPISODE_INDEX]] for p in sample_episodes(table).values()]
    began = [r for r in picked if r[S.FAULT]["kind"] != "none" and r[S.FAULT]["onset_step"] < r[S.LENGTH]]
    assert began, "no sampled episode of the tiny dynamic dataset has a fault that began"
    assert _count(grid, FAULT, tol=20) > 4


FAULT_RGB = tuple(int(P.FAULT[i : i + 2], 16) for i in (1, 3, 5))
