"""Onboard camera rendering: RGB and metric depth from one render pass, plus pooled depth."""

from __future__ import annotations

import atexit
import os
import weakref

import mujoco
import numpy as np

from orbitdata.schema import DEPTH_LOW_SIDE
from orbitdata.sim.config import CameraConfig
from orbitdata.sim.gl import make_context


def pool_depth(depth: np.ndarray, far: float, side: int = DEPTH_LOW_SIDE) -> np.ndarray:
    """Area-pool metric depth (H, W) to (side, side) metres.

    No-return pixels (0) count as the far plane, so an empty patch reads as far away rather
    than as touching the lens.
    """
    h, w = depth.shape
    filled = np.where(depth > 0, depth, np.float32(far)).astype(np.float32)
    return filled.reshape(side, h // side, side, w // side).mean(axis=(1, 3), dtype=np.float32)


_LIVE: "weakref.WeakSet[CameraRenderer]" = weakref.WeakSet()


@atexit.register
def _close_all() -> None:
    # Free GL contexts while the GL bindings still exist; at interpreter teardown the OSMesa
    # context's own finaliser fails noisily.
    for renderer in list(_LIVE):
        renderer.close()


def _release_all() -> None:
    # Before a fork (see sim.gl): no context may be left for the child to inherit.
    for renderer in list(_LIVE):
        renderer.release()


os.register_at_fork(before=_release_all)  # runs before sim.gl's hook, registered earlier


def _scene(model: mujoco.MjModel) -> mujoco.MjvScene:
    """A scene with room for every geom of ``model`` and the few MuJoCo adds: geoms past a scene's
    room are left out of the frames, with only a warning in MuJoCo's log."""
    return mujoco.MjvScene(model, maxgeom=max(64, model.ngeom + 32))


class CameraRenderer:
    """Renders the named camera of a model offscreen.

    ``render(data)`` returns ``(rgb, depth)``: uint8 (H, W, 3) and float32 (H, W) z-depth in
    metres along the optical axis, with 0 where nothing lies within [near, far]. The GL context is
    made on the first frame and again after a fork released it (:meth:`release`).
    """

    def __init__(self, model: mujoco.MjModel, camera: str, cfg: CameraConfig, backend: str | None = None):
        size = cfg.image_size
        self._size, self._backend = size, backend
        self._ctx = self._con = None
        self._closed = False
        self._model = model
        self._rect = mujoco.MjrRect(0, 0, size, size)
        self._scene = _scene(model)
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        self._rgb = np.empty((size, size, 3), np.uint8)
        self._zbuf = np.empty((size, size), np.float32)
        # Reversed-Z depth buffer -> metric z: depth = d / (z + c) (see mujoco's Renderer).
        near = np.float64(np.float32(model.vis.map.znear * model.stat.extent))
        far = np.float64(np.float32(model.vis.map.zfar * model.stat.extent))
        self._c = 0.5 * (far + near) / (far - near) - 0.5
        self._d = far * near / (far - near)
        self.near, self.far = float(near), float(far)
        self._open()
        _LIVE.add(self)

    def can_render(self, model: mujoco.MjModel) -> bool:
        """Whether this renderer's context holds ``model``'s assets: the same textures, no meshes,
        height fields or skins, the same offscreen size. Then :meth:`rebind` may take it."""
        old = self._model
        return (
            model.ntex == old.ntex
            and np.array_equal(model.tex_data, old.tex_data)
            and np.array_equal(model.tex_type, old.tex_type)
            and model.nmesh == old.nmesh == 0
            and model.nhfield == old.nhfield == 0
            and model.nskin == old.nskin == 0
            and (model.vis.global_.offwidth, model.vis.global_.offheight)
            == (old.vis.global_.offwidth, old.vis.global_.offheight)
        )

    def rebind(self, model: mujoco.MjModel, camera: str) -> None:
        """Render ``model`` from now on, keeping the GL context: making one that holds a texture costs
        more on llvmpipe than an episode's frames at 64 px. Needs :meth:`can_render`."""
        if not self.can_render(model):
            raise ValueError("the model's rendering assets differ from the ones this renderer's context holds")
        self._model = model
        self._scene = _scene(model)
        self._camera.fixedcamid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)

    def _open(self) -> None:
        self._ctx = make_context(self._size, self._size, self._backend)
        self._con = mujoco.MjrContext(self._model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)
        self._con.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR

    def render(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        if self._closed:
            raise RuntimeError("the renderer is closed")
        if self._ctx is None:
            self._open()
        self._ctx.make_current()
        mujoco.mjv_updateScene(
            self._model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        mujoco.mjr_render(self._rect, self._scene, self._con)
        mujoco.mjr_readPixels(self._rgb, self._zbuf, self._rect, self._con)
        rgb = np.flipud(self._rgb).copy()  # GL rows start at the bottom
        depth = (self._d / (np.flipud(self._zbuf).astype(np.float64) + self._c)).astype(np.float32)
        # Beyond the far plane (and empty space) the buffer holds the far value: no return.
        depth[depth >= np.float32(self.far) * np.float32(0.9999)] = 0.0
        return rgb, depth

    def release(self) -> None:
        """Free the GL context; the next frame makes a new one."""
        if self._con is not None:
            try:
                self._ctx.make_current()  # free the objects in their own context, not another renderer's
            except Exception:  # at exit the display may be gone already, and the objects with it
                pass
            self._con.free()
            self._con = None
        if self._ctx is not None:
            self._ctx.free()
            self._ctx = None

    def close(self) -> None:
        self.release()
        self._closed = True

    def __del__(self) -> None:  # contexts hold GPU/driver memory
        try:
            self.close()
        except Exception:
            pass
