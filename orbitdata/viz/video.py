"""Write RGB frames, as they come, to an H.264 .mp4 (browsers play it) or an animated .gif.

Frames stream: each one is encoded as soon as it is drawn, so a long episode never sits in
memory. The mp4 goes through the ffmpeg that ``imageio-ffmpeg`` ships (the ``viz`` extra):
H.264 (libx264), yuv420p, ``+faststart``, the combination every browser plays. GIF frames are
written one by one with Pillow, each with its own 256-colour palette.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

import numpy as np
from PIL import GifImagePlugin, Image

FORMATS = (".mp4", ".gif")
FFMPEG_HINT = "writing .mp4 needs the plotting extra: pip install 'orbitdata[viz]' (imageio-ffmpeg); or write a .gif"


def check_video_format(path: Path) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"unknown video format {suffix!r} for {path}; use one of {', '.join(FORMATS)}")
    return suffix


def _even(frame: np.ndarray) -> np.ndarray:
    """Pad to even width and height (yuv420p halves both) by repeating the last row/column."""
    h, w = frame.shape[:2]
    if h % 2 or w % 2:
        frame = np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    return np.ascontiguousarray(frame, dtype=np.uint8)


def _write_mp4(path: Path, frames: Iterable[np.ndarray], fps: float) -> int:
    try:
        import imageio_ffmpeg
    except ImportError:
        raise ImportError(FFMPEG_HINT) from None
    writer, count = None, 0
    try:
        for frame in frames:
            frame = _even(frame)
            if writer is None:
                h, w = frame.shape[:2]
                writer = imageio_ffmpeg.write_frames(
                    str(path),
                    (w, h),
                    fps=fps,
                    codec="libx264",
                    pix_fmt_in="rgb24",
                    pix_fmt_out="yuv420p",
                    macro_block_size=1,
                    quality=7,
                    ffmpeg_log_level="error",
                    output_params=["-movflags", "+faststart"],
                )
                writer.send(None)  # start ffmpeg
            writer.send(frame)
            count += 1
    finally:
        if writer is not None:
            writer.close()
    return count


def _write_gif(path: Path, frames: Iterable[np.ndarray], fps: float) -> int:
    duration = int(round(1000 / fps))  # ms per frame
    count = 0
    with open(path, "wb") as f:
        for frame in frames:
            image = Image.fromarray(np.ascontiguousarray(frame, dtype=np.uint8)).convert(
                "P", palette=Image.Palette.ADAPTIVE, colors=256
            )
            if count == 0:
                header, _ = GifImagePlugin.getheader(image, info={"loop": 0, "duration": duration})
                f.writelines(header)
            f.writelines(GifImagePlugin.getdata(image, duration=duration, include_color_table=True))
            count += 1
        f.write(b";")  # trailer
    return count


FPS_RANGE = (0.01, 1000.0)  # a GIF holds each frame for a whole number of ms, at most 65,535 cs


def check_fps(fps: float, name: str = "fps") -> float:
    """``fps`` if a video can play at it, else a ValueError naming it (``name``) and the range."""
    low, high = FPS_RANGE
    if not low <= fps <= high:  # nan fails too
        raise ValueError(f"{name} {fps:g}: give a frame rate from {low:g} to {high:g}")
    return fps


def write_video(path: Path, frames: Iterable[np.ndarray], fps: float) -> Path:
    """Write (H, W, 3) uint8 RGB ``frames`` (any iterable; consumed once, one frame at a time). The
    video is written beside ``path`` and renamed onto it once whole: a failure leaves a file
    already at ``path`` as it was."""
    path = Path(path)
    suffix = check_video_format(path)
    check_fps(fps)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{suffix}")  # the suffix names the format to ffmpeg
    try:
        count = (_write_mp4 if suffix == ".mp4" else _write_gif)(tmp, frames, fps)
        if count == 0:
            raise ValueError(f"no frames to write to {path}")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
