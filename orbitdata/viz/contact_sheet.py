"""A one-page picture of an episode: key frames (RGB over depth), both maps and the time plots.

Key frames are evenly spaced from the first to the last frame and numbered; the same numbers
mark where they were taken on the maps and when on the time plots. On the dynamic tier the maps
show each piece of debris' track (and its outline at the end), and the maps and the time plots
mark the thruster fault's onset.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from orbitdata import schema as S
from orbitdata.load.episodes import Episode
from orbitdata.viz import plots as P
from orbitdata.viz.topdown import PlaneMap, draw_numbered, paired_views


def key_frames(length: int, count: int = 6) -> list[int]:
    """``count`` frame indices evenly spaced over an episode, first and last included."""
    return sorted({int(round(x)) for x in np.linspace(0, length - 1, min(count, length))})


class ContactSheet:
    """Renders ``image``: (H, W, 3) uint8 RGB. ``path_pixels(view)`` says where the path is drawn."""

    WIDTH, HEIGHT = 1400, 1220
    FRAME = 192  # px, side of each key frame panel
    PITCH = 212  # px between key frame columns

    def __init__(self, ep: Episode, count: int = 6):
        self.ep = ep
        self.frames = key_frames(len(ep), count)
        rgb, depth = ep.rgb(self.frames), ep.depth(self.frames)
        poses, onset = ep.obstacle_poses, P.fault_onset(ep)
        colours = P.DepthColours(P.DepthColours.range_for(depth))
        with P.theme():
            fig = P.figure(self.WIDTH, self.HEIGHT)
            fig.text(0.5, 1 - 22 / self.HEIGHT, ep.title(), ha="center", va="center", fontsize=14, weight="bold")
            fig.text(
                0.5, 1 - 48 / self.HEIGHT, self._subtitle(), ha="center", va="center", fontsize=10, color="#b0b0bc"
            )
            cams, deps = [], []
            for n, t in enumerate(self.frames, 1):
                x = 40 + (n - 1) * self.PITCH
                cam = P.add_axes(fig, x, 90, self.FRAME, self.FRAME)
                dep = P.add_axes(fig, x, 300, self.FRAME, self.FRAME)
                cam.set_title(f"{n}:  t = {ep.times[t]:.2f} s  (frame {t})", fontsize=9)
                for ax in (cam, dep):
                    ax.set_axis_off()
                cams.append(cam)
                deps.append(dep)
            fig.text(24 / self.WIDTH, 1 - 186 / self.HEIGHT, "onboard RGB", rotation=90, ha="center", va="center")
            fig.text(24 / self.WIDTH, 1 - 396 / self.HEIGHT, "depth", rotation=90, ha="center", va="center")
            colours.colorbar(
                fig, P.add_axes(fig, 40 + (len(self.frames) - 1) * self.PITCH + self.FRAME + 18, 300, 12, self.FRAME)
            )
            top = P.add_axes(fig, 70, 560, 590, 300)
            side = P.add_axes(fig, 770, 560, 590, 300)
            self.top, self.side = paired_views(
                ep.scenario, P.box_of(fig, top).size, P.box_of(fig, side).size, P.map_points(ep)
            )
            P.setup_map_axes(top, self.top, "top view (obstacles to scale)")
            P.setup_map_axes(side, self.side, "side view (obstacles to scale)")
            P.map_legend(
                fig,
                (0.5, 1 - 908 / self.HEIGHT),
                collision=ep.collision_at is not None,
                marks=True,
                ncol=7 if poses is None else 9,
                debris=poses is not None,
                fault=onset is not None,
            )
            ep_axes = {
                "speed": P.add_axes(fig, 60, 970, 270, 190),
                "clearance": P.add_axes(fig, 400, 970, 270, 190),
                "thrust": P.add_axes(fig, 740, 970, 250, 190),
                "thrust_bar": P.add_axes(fig, 998, 970, 8, 190),
                "fuel": P.add_axes(fig, 1100, 970, 260, 190),
            }
            P.plot_signals(fig, ep_axes, ep, marks=self.frames)
            image = P.render(fig)
            self.boxes = {"top": P.box_of(fig, top), "side": P.box_of(fig, side)}
            self.frame_boxes = [(P.box_of(fig, cam), P.box_of(fig, dep)) for cam, dep in zip(cams, deps)]
        for (cam, dep), frame_rgb, frame_depth in zip(self.frame_boxes, rgb, depth):
            cam.paste(image, P.fit(frame_rgb, cam.size))
            dep.paste(image, P.fit(colours(frame_depth), dep.size))
            if not (frame_depth > 0).any():  # a black panel is confusing without a word
                P.note(image, dep, P.NO_RETURN)
        key = ep.positions[self.frames]
        for name, view in self.views.items():
            panel = view.background()
            if poses is not None:
                view.draw_tracks(panel, poses)
                view.draw_debris(panel, poses[-1])
            for t in self.frames:  # which way the camera looked in each key frame (under the path)
                view.draw_heading(panel, ep.positions[t], ep.camera_axis[t], length_m=0.8)
            view.draw_path(panel, ep.positions, ep.collision_at)
            if onset is not None:
                view.draw_fault(panel, ep.positions[onset])
            draw_numbered(panel, view, key)
            self.boxes[name].paste(image, panel)
        self.image = image

    @property
    def views(self) -> dict[str, PlaneMap]:
        return {"top": self.top, "side": self.side}

    def _subtitle(self) -> str:
        ep, m = self.ep, self.ep.meta
        flown = float(np.linalg.norm(np.diff(ep.positions, axis=0), axis=1).sum())
        parts = [
            f"goal {np.linalg.norm(m[S.GOAL]):.1f} m away (radius {m[S.GOAL_RADIUS]:.1f} m)",
            f"initial speed {np.linalg.norm(m[S.INITIAL_VELOCITY]):.2f} m/s",
            f"flew {flown:.1f} m",
            f"closest approach {ep.clearance.min():.2f} m",
            f"fuel used {100 * (ep.fuel[0] - ep.fuel[-1]):.1f}%",
            f"seed {m[S.SEED]}",
        ]
        fault = P.episode_fault(ep)
        if fault is not None:
            when = fault["onset_step"] * S.DT
            began = fault["onset_step"] < len(ep)
            parts.insert(
                -1,
                f"{P.fault_label(fault)} " + (f"from {when:.2f} s" if began else f"due at {when:.2f} s, after the end"),
            )
        return "   ·   ".join(parts)

    def track_pixels(self, view: str, piece: int) -> np.ndarray:
        """(L, 2) image pixels (column, row) where debris ``piece``'s track is drawn in ``view``."""
        box = self.boxes[view]
        return self.views[view].polyline(self.ep.obstacle_poses[:, piece, :3]) + [box.x0, box.y0]

    def path_pixels(self, view: str) -> np.ndarray:
        """(L, 2) image pixels (column, row) where the whole path is drawn in ``view``."""
        box = self.boxes[view]
        return self.views[view].polyline(self.ep.positions) + [box.x0, box.y0]

    def save(self, path: Path) -> Path:
        Image.fromarray(self.image).save(path, optimize=True)
        return Path(path)
