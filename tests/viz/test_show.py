"""`orbitdata show`: videos and contact sheets open, show the right episode, and fail clearly."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitdata.cli.app import app
from orbitdata.load.episodes import EpisodeNotFound, load_episode, read_episodes
from orbitdata.viz import plots as P
from orbitdata.viz.contact_sheet import ContactSheet, key_frames
from orbitdata.viz.show import EpisodeVideo, show_episode
from orbitdata.viz.topdown import PATH

runner = CliRunner()


@pytest.fixture(scope="module")
def shortest(tiny_dataset_master) -> int:
    """The index of the shortest episode (fast to render)."""
    t = read_episodes(tiny_dataset_master, [S.EPISODE_INDEX, S.LENGTH]).to_pylist()
    return min(t, key=lambda r: (r[S.LENGTH], r[S.EPISODE_INDEX]))[S.EPISODE_INDEX]


@pytest.fixture(scope="module")
def video(tiny_dataset_master, shortest) -> EpisodeVideo:
    return EpisodeVideo(load_episode(tiny_dataset_master, shortest))


def _path_share(img: np.ndarray, pixels: np.ndarray, tol: int = 60) -> float:
    """Share of ``pixels`` (N, 2) (column, row) whose colour is the path's."""
    colours = img[pixels[:, 1], pixels[:, 0]].astype(int)
    return float((np.abs(colours - PATH).max(axis=1) <= tol).mean())


def _inner(pixels: np.ndarray, skip: int = 4) -> np.ndarray:
    """Drop the ends, where the start cross, the position dot and the arrow cover the path."""
    return pixels[skip:-skip]


def test_every_frame_shows_this_episodes_camera(video):
    ep = video.ep
    assert len(video) == len(ep)
    for t in (0, len(ep) // 2, len(ep) - 1):
        frame = video.frame(t)
        assert frame.shape == (720, 1280, 3) and frame.dtype == np.uint8
        box = video.boxes["camera"]
        expected = P.fit(ep.rgb([t])[0], box.size)
        np.testing.assert_array_equal(frame[box.y0 : box.y1, box.x0 : box.x1], expected)


@pytest.mark.parametrize("view", ["top", "side"])
def test_the_drawn_path_follows_the_state_positions(video, view):
    ep = video.ep
    last = len(ep) - 1
    frame = video.frame(last)
    pixels = video.path_pixels(view, last)
    box = video.boxes[view]
    assert (pixels[:, 0] >= box.x0).all() and (pixels[:, 0] < box.x1).all()
    assert (pixels[:, 1] >= box.y0).all() and (pixels[:, 1] < box.y1).all()
    assert _path_share(frame, _inner(pixels)) > 0.9
    # the pixels map back to the state columns (p_x, p_y / p_z)
    metres = video.views[view].world(pixels - [box.x0, box.y0])
    axes = list(video.views[view].axes)
    np.testing.assert_allclose(metres, ep.states[:, axes], atol=0.75 / video.views[view].scale)
    # and a path displaced by a few pixels is not what was drawn
    assert _path_share(frame, _inner(pixels) + [0, 9]) < 0.5


def test_the_path_is_drawn_only_up_to_the_current_frame(video):
    ep = video.ep
    mid = len(ep) // 2
    frame = video.frame(mid)
    future = video.path_pixels("top", len(ep) - 1)[mid + 6 : -4]
    past = video.path_pixels("top", mid)[4:-6]
    assert np.abs(np.diff(future, axis=0)).sum() > 10  # the CubeSat moves visibly after mid, so the check below bites
    assert _path_share(frame, past) > 0.9
    assert _path_share(frame, future) < 0.5


def test_mp4_has_one_frame_per_step(tiny_dataset_master, shortest, tmp_path):
    out = show_episode(tiny_dataset_master, shortest, tmp_path / "ep.mp4")
    cap = cv2.VideoCapture(str(out))
    try:
        n = 0
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            assert frame.shape == (720, 1280, 3)
            n += 1
    finally:
        cap.release()
    assert n == len(load_episode(tiny_dataset_master, shortest))


def test_an_mp4_from_orbitdata_show_is_h264_that_browsers_play(tiny_dataset_master, shortest, tmp_path):
    import imageio_ffmpeg  # the test extra installs it: a broken import fails here, it is not skipped

    out = tmp_path / "ep.mp4"
    res = runner.invoke(app, ["show", str(tiny_dataset_master), "--episode", str(shortest), "--out", str(out)])
    assert res.exit_code == 0, res.output
    probe = imageio_ffmpeg.read_frames(str(out))  # ffmpeg's own reading of the stream header
    meta = next(probe)
    probe.close()
    assert meta["codec"].startswith("h264"), meta["codec"]
    assert meta["pix_fmt"].startswith("yuv420p"), meta["pix_fmt"]  # the pixel format browsers decode
    assert meta["size"] == (1280, 720) and meta["fps"] == 25
    assert out.read_bytes()[4:8] == b"ftyp"  # an MP4 container


def test_videos_stream_frames_as_they_are_drawn(tmp_path):
    """The writer pulls one frame at a time: the file (written beside the video, renamed onto it
    once whole) grows while frames are still to come."""
    from orbitdata.viz.video import write_video

    rng = np.random.default_rng(0)
    path, sizes = tmp_path / "v.gif", []
    writing = tmp_path / ".v.tmp.gif"

    def frames():
        for _ in range(60):
            sizes.append(writing.stat().st_size if writing.exists() else 0)
            yield rng.integers(0, 256, (64, 96, 3), dtype=np.uint8)  # noise: ~6 KB a frame in the GIF

    write_video(path, frames(), 25)
    assert len(sizes) == 60 and 0 < sizes[30] < sizes[59] < path.stat().st_size, sizes  # written as it goes
    with Image.open(path) as im:
        assert im.n_frames == 60 and im.size == (96, 64)


def test_gif_has_one_frame_per_step(tiny_dataset_master, shortest, tmp_path):
    out = show_episode(tiny_dataset_master, shortest, tmp_path / "ep.gif")
    with Image.open(out) as im:
        assert im.n_frames == len(load_episode(tiny_dataset_master, shortest))
        assert im.size == (960, 540)


def test_png_is_a_contact_sheet_of_this_episode(tiny_dataset_master, shortest, tmp_path):
    out = show_episode(tiny_dataset_master, shortest, tmp_path / "ep.png")
    with Image.open(out) as im:
        assert im.size == (ContactSheet.WIDTH, ContactSheet.HEIGHT)
        image = np.asarray(im.convert("RGB"))
    ep = load_episode(tiny_dataset_master, shortest)
    sheet = ContactSheet(ep)
    np.testing.assert_array_equal(image, sheet.image)
    assert sheet.frames == key_frames(len(ep)) and sheet.frames[0] == 0 and sheet.frames[-1] == len(ep) - 1
    for t, (cam, _) in zip(sheet.frames, sheet.frame_boxes):
        np.testing.assert_array_equal(image[cam.y0 : cam.y1, cam.x0 : cam.x1], P.fit(ep.rgb([t])[0], cam.size))
    for view in ("top", "side"):
        pixels = sheet.path_pixels(view)
        # key-frame dots sit on the path: leave out the points next to them
        near_key = np.zeros(len(pixels), bool)
        for t in sheet.frames:
            near_key |= np.abs(pixels - pixels[t]).max(axis=1) <= 6
        assert _path_share(image, pixels[~near_key]) > 0.85


def test_key_frames_cover_the_episode():
    assert key_frames(100) == [0, 20, 40, 59, 79, 99]
    assert key_frames(3) == [0, 1, 2]
    assert key_frames(1) == [0]


def test_unknown_format_and_bad_episode_are_errors(tiny_dataset_master, tmp_path):
    with pytest.raises(ValueError, match=r"unknown format '\.avi'.*\.mp4.*\.gif.*\.png"):
        show_episode(tiny_dataset_master, 0, tmp_path / "ep.avi")
    with pytest.raises(EpisodeNotFound, match="indices 0 to 5"):
        show_episode(tiny_dataset_master, 42, tmp_path / "ep.png")
    assert not list(tmp_path.iterdir())


def test_show_cli(tiny_dataset_master, shortest, tmp_path):
    out = tmp_path / "sheet.png"
    res = runner.invoke(app, ["show", str(tiny_dataset_master), "--episode", str(shortest), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.exists() and str(out) in res.output


@pytest.mark.parametrize(
    "args, code, message",
    [
        (["--episode", "0", "--out", "x.avi"], 2, "unknown format '.avi'"),
        (["--episode", "0", "--out", "x"], 2, "unknown format (no suffix)"),
        (["--episode", "77", "--out", "x.png"], 2, "episode 77 is not in"),
        (["--out", "x.png"], 2, "pass --episode N"),
        (["--episode", "0", "--out", "x.mp4", "--fps", "0"], 2, "--fps 0"),
        (["--episode", "0", "--out", "x.gif", "--fps", "0.0001"], 2, "give a frame rate from 0.01 to 1000"),
        (["--episode", "0", "--out", "x.mp4", "--fps", "inf"], 2, "--fps inf"),
    ],
)
def test_show_cli_errors(tiny_dataset_master, tmp_path, args, code, message):
    res = runner.invoke(
        app, ["show", str(tiny_dataset_master), *[str(tmp_path / a) if a.startswith("x") else a for a in args]]
    )
    assert res.exit_code == code, res.output
    assert message in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_show_cli_on_a_missing_folder(tmp_path):
    res = runner.invoke(app, ["show", str(tmp_path / "nope"), "--episode", "0", "--out", str(tmp_path / "x.png")])
    assert res.exit_code == 2 and "no dataset folder at" in res.output  # a usage error, as everywhere


def test_without_matplotlib_the_error_says_how_to_install(tiny_dataset_master, tmp_path, monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "matplotlib", None)
    with pytest.raises(ImportError, match=r"pip install 'orbitdata\[viz\]'"):
        P.require_matplotlib()
    res = runner.invoke(app, ["show", str(tiny_dataset_master), "--episode", "0", "--out", str(tmp_path / "x.png")])
    assert res.exit_code == 1 and "pip install 'orbitdata[viz]'" in res.output


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_a_video_that_fails_half_way_leaves_the_file_it_would_replace(tmp_path, suffix):
    from orbitdata.viz.video import write_video

    frame = np.zeros((8, 8, 3), np.uint8)
    out = tmp_path / f"keep{suffix}"
    write_video(out, [frame, frame], 25)
    before = out.read_bytes()

    def frames_then_a_failure():
        yield frame
        raise RuntimeError("the episode could not be read")

    with pytest.raises(RuntimeError):
        write_video(out, frames_then_a_failure(), 25)
    assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == [out.name]


def test_a_damaged_shard_is_named_with_the_way_out(tiny_dataset, tmp_path):
    """show (and shard) name a file pyarrow cannot read and send the user to validate."""
    shard = next((tiny_dataset / "data").glob("train-*.parquet"))
    shard.write_bytes(shard.read_bytes()[: shard.stat().st_size // 2])  # cut short, as a failed download leaves it
    for args in (
        ["show", str(tiny_dataset), "--episode", "0", "--out", str(tmp_path / "ep.png")],
        ["shard", str(tiny_dataset)],
    ):
        res = runner.invoke(app, args)
        lines = [line for line in res.output.splitlines() if line.strip()]
        assert res.exit_code == 1 and "Traceback" not in res.output, res.output
        rel = shard.relative_to(tiny_dataset).as_posix()
        assert rel in lines[-1] and "is damaged; run `orbitdata validate`" in lines[-1], lines[-1]
