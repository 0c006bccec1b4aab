"""Pick a headless OpenGL backend once per process: EGL first, OSMesa as the fallback.

PyOpenGL binds its platform on first import, so a failed EGL attempt cannot be followed by
OSMesa in the same process. We therefore probe in a short subprocess (once; the answer is
exported in $MUJOCO_GL so worker processes inherit it) before importing any GL module.

A GL driver does not survive ``fork``: a child of a process that has rendered would wait forever
for the parent's rasteriser threads (an async Gymnasium vector env forks its workers). Before a
fork, the renderers free their contexts (``sim.render``) and the EGL display is terminated here,
so the child starts its own and the parent makes new contexts on its next frame. OSMesa keeps
its state for the process's lifetime: a child forked after it rendered refuses to render, in one
line, instead of hanging.
"""

from __future__ import annotations

import os
import subprocess
import sys

BACKENDS = ("egl", "osmesa")
_PROBE = "from mujoco.{b} import GLContext; c = GLContext(16, 16); c.make_current(); c.free()"
INSTALL_HINT = (
    "no headless OpenGL backend works: install EGL with Mesa "
    "(Debian/Ubuntu: `apt-get install libegl1 libgl1-mesa-dri`) or OSMesa "
    "(`apt-get install libosmesa6`), or set MUJOCO_GL to a backend that works here"
)


class RenderBackendError(RuntimeError):
    """No OpenGL backend could create a context."""


_used: str | None = None  # the backend this process has made contexts with
_inherited: str | None = None  # in a forked child: the parent's backend, whose state could not be released


def _release_before_fork() -> None:
    """Terminate the EGL display so a forked child starts afresh. ``sim.render``'s hook has freed
    every context made here by then (a context made outside orbitdata would not survive this)."""
    global _used
    if _used != "egl":
        return
    egl = sys.modules.get("mujoco.egl")
    if egl is not None and egl.EGL_DISPLAY is not None:
        egl.EGL.eglTerminate(egl.EGL_DISPLAY)
        egl.EGL_DISPLAY = None  # the next context initialises a new display
    _used = None


def _after_fork_in_child() -> None:
    global _inherited
    if _used is not None:
        _inherited = _used


os.register_at_fork(before=_release_before_fork, after_in_child=_after_fork_in_child)


def _works(backend: str) -> tuple[bool, str]:
    env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend)
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE.format(b=backend)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return proc.returncode == 0, proc.stderr.strip().splitlines()[-1:] and proc.stderr.strip().splitlines()[-1] or ""


def select_backend(preferred: str | None = None) -> str:
    """Return the backend to use and export it, probing EGL then OSMesa if none is set."""
    chosen = (preferred or os.environ.get("MUJOCO_GL", "")).lower().strip()
    if chosen:
        if chosen in BACKENDS:
            os.environ["MUJOCO_GL"] = chosen
            os.environ.setdefault("PYOPENGL_PLATFORM", chosen)
        return chosen
    errors = []
    for backend in BACKENDS:
        ok, err = _works(backend)
        if ok:
            os.environ["MUJOCO_GL"] = backend
            os.environ["PYOPENGL_PLATFORM"] = backend
            return backend
        errors.append(f"{backend}: {err}")
    raise RenderBackendError(f"{INSTALL_HINT} ({'; '.join(errors)})")


def make_context(width: int, height: int, preferred: str | None = None):
    """A current offscreen GL context of at least ``width`` x ``height``."""
    global _used
    if _inherited is not None:
        raise RenderBackendError(
            f"this process was forked from one that had rendered with MUJOCO_GL={_inherited}, "
            "whose state does not survive fork; start it with the 'spawn' start method (e.g. "
            "gym.make_vec(..., vector_kwargs={'context': 'spawn'})), or render with EGL"
        )
    backend = select_backend(preferred)
    try:
        if backend == "egl":
            from mujoco.egl import GLContext
        elif backend == "osmesa":
            from mujoco.osmesa import GLContext
        else:
            from mujoco.gl_context import GLContext
        ctx = GLContext(width, height)
        ctx.make_current()
    except Exception as exc:  # the GL stack reports many different error types
        raise RenderBackendError(f"MUJOCO_GL={backend} failed: {exc}; {INSTALL_HINT}") from exc
    _used = backend
    return ctx
