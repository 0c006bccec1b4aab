"""Headless OpenGL: EGL by default, OSMesa as the fallback, a clear error when neither works."""

import os
import signal
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


FORK = """
import os
from orbitdata.sim import CameraConfig, CubeSatEnv, SimConfig
env = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=32)))
first = env.reset(seed=4)[0]["image"]
pid = os.fork()
if pid == 0:
    try:
        child = CubeSatEnv(SimConfig(camera=CameraConfig(image_size=32)))
        print("child", "same" if (child.reset(seed=4)[0]["image"] == first).all() else "different", flush=True)
    except Exception as exc:
        print("child", type(exc).__name__, exc, flush=True)
    os._exit(0)
os.waitpid(pid, 0)
print("parent", "same" if (env.reset(seed=4)[0]["image"] == first).all() else "different", flush=True)
"""


@pytest.mark.parametrize(
    "backend, child",
    [
        ("egl", "child same"),  # the display is released before the fork: the child renders the same pixels
        ("osmesa", "child RenderBackendError this process was forked from one that had rendered with MUJOCO_GL=osmesa"),
    ],
)
def test_a_child_forked_after_rendering_renders_or_says_why_it_cannot(backend, child):
    """It used to wait forever in the renderer; the script runs in its own process group, killed
    whole if it does not finish."""
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    env["MUJOCO_GL"] = backend
    proc = subprocess.Popen(
        [sys.executable, "-c", FORK],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=120)  # seconds normally; a guard against a hang
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"a forked child hung rendering with {backend}")
    lines = out.strip().splitlines()
    assert proc.returncode == 0 and len(lines) == 2, err
    assert lines[0].startswith(child) and lines[1] == "parent same"
