"""Write RGB frames to .mp4 (OpenCV) or .gif (Pillow), no extra dependencies."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image

FORMATS = (".mp4", ".gif")


def write_video(path: Path, frames: list[np.ndarray], fps: float) -> Path:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"unknown video format {suffix!r} for {path}; use one of {', '.join(FORMATS)}")
    if not frames:
        raise ValueError(f"no frames to write to {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    h, w = frames[0].shape[:2]
    if suffix == ".mp4":
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        if not writer.isOpened():
            raise RuntimeError(f"OpenCV cannot write mp4 to {path}; use a .gif instead")
        for f in frames:
            writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
        writer.release()
    else:
        images = [Image.fromarray(f) for f in frames]
        images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    return path
