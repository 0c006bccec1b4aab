"""``orbitdata show``: one episode as a video (.mp4 / .gif) or a contact sheet (.png).

Each video frame shows the onboard RGB camera beside colour-mapped depth, a top-down and a side
view of the path so far (obstacles to scale, goal, camera axis, the collision point at the end)
and time plots of speed, clearance, thrust and fuel with a cursor at the current time. On the
dynamic tier the maps also show each piece of debris' track and where it is now, and the plots
and the maps mark the thruster fault's onset.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from orbitdata import schema as S
from orbitdata.codecs import decode_depth, decode_rgb
from orbitdata.load.episodes import Episode, load_episode
from orbitdata.schema import FPS, OUTCOME
from orbitdata.viz import plots as P
from orbitdata.viz.topdown import PlaneMap, paired_views
from orbitdata.viz.video import FORMATS as VIDEO_FILE_FORMATS
from orbitdata.viz.video import write_video

VIDEO_FORMATS = VIDEO_FILE_FORMATS
FORMATS = VIDEO_FORMATS + (".png",)
TEXT = (230, 230, 238)  # RGB, the theme's text colour


def check_format(path: Path) -> str:
    """The output's suffix, or a ValueError that lists the formats."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(
            f"cannot write {path}: unknown format {repr(suffix) if suffix else '(no suffix)'}; "
            "use .mp4 or .gif for a video, or .png for a contact sheet"
        )
    return suffix


class EpisodeVideo:
    """Renders the frames of one episode's video; ``frame(t)`` is an (H, W, 3) uint8 RGB image."""

    WIDTH, HEIGHT = 1280, 720
    CAM = 256  # px, side of the camera and depth panels; small frames are enlarged in whole pixels

    def __init__(self, ep: Episode, scale: float = 1.0):
        self.ep = ep
        self.k = scale  # gifs use a smaller frame
        # Frames stay encoded (a few KB each) and are decoded as the writer asks for them.
        self.rgb_bytes, self.depth_bytes = ep.encoded(S.IMAGE), ep.encoded(S.DEPTH)
        sample = [decode_depth(b) for b in self.depth_bytes[:: max(1, len(ep) // 25)]]
        self.colours = P.DepthColours(P.DepthColours.range_for(sample))
        self.poses = ep.obstacle_poses  # (L, N, 7) on the dynamic tier, else None
        self.onset = P.fault_onset(ep)
        with P.theme():
            fig = P.figure(self.WIDTH, self.HEIGHT, scale)
            fig.text(0.5, 1 - 22 / self.HEIGHT, ep.title(), ha="center", va="center", fontsize=13, weight="bold")
            cam = P.add_axes(fig, 30, 70, self.CAM, self.CAM)
            dep = P.add_axes(fig, 316, 70, self.CAM, self.CAM)
            cbar = P.add_axes(fig, 580, 70, 12, self.CAM)
            top = P.add_axes(fig, 690, 70, 265, 236)
            side = P.add_axes(fig, 1000, 70, 265, 236)
            for ax, title in ((cam, f"onboard camera ({sample[0].shape[1]} px RGB)"), (dep, "depth")):
                ax.set_axis_off()
                ax.set_title(title)
            self.colours.colorbar(fig, cbar)
            self.top, self.side = paired_views(
                ep.scenario, P.box_of(fig, top).size, P.box_of(fig, side).size, P.map_points(ep)
            )
            P.setup_map_axes(top, self.top, "top view")
            P.setup_map_axes(side, self.side, "side view")
            P.map_legend(
                fig,
                ((650 + 1265) / 2 / self.WIDTH, 1 - 370 / self.HEIGHT),
                collision=ep.collision_at is not None,
                heading=True,
                ncol=3 if self.poses is None else 4,
                debris=self.poses is not None,
                fault=self.onset is not None,
            )
            sig = {
                "speed": P.add_axes(fig, 60, 440, 250, 220),
                "clearance": P.add_axes(fig, 370, 440, 250, 220),
                "thrust": P.add_axes(fig, 690, 440, 240, 220),
                "thrust_bar": P.add_axes(fig, 938, 440, 8, 220),
                "fuel": P.add_axes(fig, 1045, 440, 215, 220),
            }
            P.plot_signals(fig, sig, ep)
            self.background = P.render(fig)
            self.boxes = {
                name: P.box_of(fig, ax) for name, ax in (("camera", cam), ("depth", dep), ("top", top), ("side", side))
            }
            self.cursor = P.TimeCursor.of(fig, [sig[n] for n in ("speed", "clearance", "thrust", "fuel")])
        self.map_background = {"top": self.top.background(), "side": self.side.background()}
        if self.poses is not None:
            for name, view in self.views.items():
                view.draw_tracks(self.map_background[name], self.poses)
        assert self.background.shape[:2] == (round(self.HEIGHT * scale), round(self.WIDTH * scale))

    def __len__(self) -> int:
        return len(self.ep)

    @property
    def views(self) -> dict[str, PlaneMap]:
        return {"top": self.top, "side": self.side}

    def path_pixels(self, view: str, t: int) -> np.ndarray:
        """(t+1, 2) frame pixels (column, row) where the path up to frame ``t`` is drawn in ``view``."""
        box = self.boxes[view]
        return self.views[view].polyline(self.ep.positions[: t + 1]) + [box.x0, box.y0]

    def track_pixels(self, view: str, piece: int) -> np.ndarray:
        """(L, 2) frame pixels (column, row) where debris ``piece``'s track is drawn in ``view``."""
        box = self.boxes[view]
        return self.views[view].polyline(self.poses[:, piece, :3]) + [box.x0, box.y0]

    def frame(self, t: int) -> np.ndarray:
        ep = self.ep
        img = self.background.copy()
        rgb, depth = decode_rgb(self.rgb_bytes[t]), decode_depth(self.depth_bytes[t])
        self.boxes["camera"].paste(img, P.fit(rgb, self.boxes["camera"].size))
        self.boxes["depth"].paste(img, P.fit(self.colours(depth), self.boxes["depth"].size))
        if not (depth > 0).any():  # a black panel is confusing without a word
            P.note(img, self.boxes["depth"], P.NO_RETURN, self.k)
        last = t == len(ep) - 1
        for name, view in self.views.items():
            panel = self.map_background[name].copy()
            if self.poses is not None:
                view.draw_debris(panel, self.poses[t])
            view.draw_path(panel, ep.positions[: t + 1], ep.collision_at if last else None)
            if self.onset is not None and t >= self.onset:
                view.draw_fault(panel, ep.positions[self.onset])
            view.draw_heading(panel, ep.positions[t], ep.camera_axis[t])
            self.boxes[name].paste(img, panel)
        self.cursor.draw(img, t * ep.times[1] if len(ep) > 1 else 0.0)
        status = f"t = {ep.times[t]:5.2f} s   frame {t + 1:3d} / {len(ep)}"
        if last:
            status += f"   {ep.meta[OUTCOME].upper()}"
        if self.onset is not None and t >= self.onset:
            status += f"   {P.fault_label(P.episode_fault(ep))}"
        cam = self.boxes["camera"]
        cv2.putText(
            img,
            status,
            (cam.x0, cam.y1 + int(28 * self.k)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.6 * self.k,
            TEXT,
            1,
            cv2.LINE_AA,
        )
        return img

    def __getitem__(self, t: int) -> np.ndarray:
        if not -len(self) <= t < len(self):
            raise IndexError(f"frame {t} out of range for {len(self)} frames")
        return self.frame(t % len(self))

    def __iter__(self):  # frames are drawn as the writer asks for them, so an mp4 streams
        return (self.frame(t) for t in range(len(self)))


def show_episode(root: Path, index: int, out: Path, fps: float = FPS) -> Path:
    """Render episode ``index`` of the dataset at ``root`` to ``out`` (.mp4, .gif or .png)."""
    suffix = check_format(out)
    ep = load_episode(root, index)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".png":
        from orbitdata.viz.contact_sheet import ContactSheet

        ContactSheet(ep).save(out)
        return out
    video = EpisodeVideo(ep, scale=0.75 if suffix == ".gif" else 1.0)
    return write_video(out, video, fps)
