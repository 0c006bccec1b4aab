"""Headless OpenGL: EGL by default, OSMesa as the fallback, a clear error when neither works."""

import hashlib
import os
import subprocess
import sys

import pytest

from orbitdata.sim import gl

SCRIPT = """
import hashlib
from orbitdata.sim import CameraConfig, CubeSatEnv, SimConfig
env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=32)))
obs, _ = env.reset(seed=4)
import os
print(os.environ["MUJOCO_GL"], hashlib.sha256(obs["image"].tobytes() + obs["depth"].tobytes()).hexdigest())
"""


def _render_in_subprocess(backend: str | None) -> tuple[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    if backend:
        env["MUJOCO_GL"] = backend
    out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=True)
    chosen, digest = out.stdout.split()
    return chosen, digest


def test_egl_is_the_default_and_osmesa_renders_the_same_pixels():
    chosen, egl = _render_in_subprocess(None)
    assert chosen == "egl"
    chosen, osmesa = _render_in_subprocess("osmesa")
    assert chosen == "osmesa"
    assert osmesa == egl  # both are Mesa llvmpipe


def test_falls_back_to_osmesa_when_egl_fails(monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    monkeypatch.setattr(gl, "_works", lambda b: (b == "osmesa", "" if b == "osmesa" else "EGL_NOT_INITIALIZED"))
    try:
        assert gl.select_backend() == "osmesa"
    finally:
        os.environ["MUJOCO_GL"] = "egl"  # this test process has bound EGL already


def test_clear_error_names_the_packages_to_install(monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.setattr(gl, "_works", lambda b: (False, "no display"))
    with pytest.raises(gl.RenderBackendError, match="apt-get install libegl1 libgl1-mesa-dri.*libosmesa6"):
        gl.select_backend()
