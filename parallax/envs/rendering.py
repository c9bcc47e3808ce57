"""Headless OpenGL rendering of the robot's eye (paper §3.2: the left-eye image I(t)).

A small renderer that keeps one MuJoCo render context and one scene per physics, in one OpenGL
context shared by all environments, so rendering an eye frame re-creates nothing, which keeps it
cheap on a CPU (Mesa); dm_control's generic ``physics.render`` re-creates its camera and scene on
every call and opens one OpenGL context per physics. It also re-uploads a texture after its
pixels changed, which is how the stimulus is swapped without recompiling.

Every OpenGL call of the process runs on one thread, :func:`gl_thread` (an OpenGL context is
current in one thread at a time). Renderers may be used from any thread: their calls are handed
to it and waited for, or run at once when already on it. MuJoCo releases the GIL while it
renders, so the experiment hands whole environment steps to this thread
(:meth:`GLThread.submit`) and encodes the previous frames meanwhile.

Backend: see ``parallax.envs.backend`` (the user's ``MUJOCO_GL``, egl by default, one clear
error when it cannot render).
"""

from __future__ import annotations

import atexit
import os
import queue
import threading
import weakref
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

import numpy as np

from parallax.envs.backend import INSTALL_HINT, gl_backend, import_mujoco, open_gl_context

mujoco = import_mujoco()

#: Geom groups the eye sees: panel (0) and background (2); the robot's body (1) is behind the
#: eyes, the floor (3) is for the side view, markers (4) for tests and pictures.
EYE_GEOM_GROUPS = (0, 2)


#: Nominal size of the shared contexts: each MuJoCo render context has its own offscreen
#: framebuffer.
_NOMINAL_SIZE = 2048

_LIVE_RENDERERS: weakref.WeakSet[SceneRenderer] = weakref.WeakSet()
_shared_context: Any = None

Result = TypeVar("Result")


class GLThread:
    """The one thread that makes the process's OpenGL calls; jobs run one at a time, in order."""

    def __init__(self) -> None:
        self._jobs: queue.SimpleQueue[tuple[Future, Callable[..., Any], tuple]] = (
            queue.SimpleQueue()
        )
        # A daemon: it must not keep a finished program alive, and it still serves the exit hook
        # below (daemon threads run until the interpreter tears down, after the atexit hooks).
        self._thread = threading.Thread(target=self._serve, name="parallax-gl", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while True:
            future, function, arguments = self._jobs.get()
            if future.set_running_or_notify_cancel():
                _run_into(future, function, arguments)

    @property
    def is_current(self) -> bool:
        return threading.current_thread() is self._thread

    def submit(self, function: Callable[..., Result], *arguments: Any) -> Future[Result]:
        """Run ``function(*arguments)`` on this thread after the jobs before it; on this thread
        itself it runs at once (a job may render)."""
        future: Future = Future()
        if self.is_current:
            future.set_running_or_notify_cancel()
            _run_into(future, function, arguments)
        else:
            self._jobs.put((future, function, arguments))
        return future

    def call(self, function: Callable[..., Result], *arguments: Any) -> Result:
        """``submit`` and wait: the result, or the job's exception raised here."""
        if not (self.is_current or self._thread.is_alive()):
            # At interpreter teardown the daemon is gone; waiting would hang the exit.
            raise RuntimeError("the GL thread has stopped")
        return self.submit(function, *arguments).result()


def _run_into(future: Future, function: Callable[..., Any], arguments: tuple) -> None:
    try:
        future.set_result(function(*arguments))
    except BaseException as error:  # noqa: BLE001 — handed to the waiting caller
        future.set_exception(error)


_gl_thread: GLThread | None = None
_gl_thread_pid: int | None = None
_gl_thread_lock = threading.Lock()


def gl_thread() -> GLThread:
    """This process's OpenGL thread, started on first use (and again in a forked child)."""
    global _gl_thread, _gl_thread_pid
    with _gl_thread_lock:
        if _gl_thread is None or _gl_thread_pid != os.getpid():
            _gl_thread, _gl_thread_pid = GLThread(), os.getpid()
    return _gl_thread


def _close_everything() -> None:
    global _shared_context
    for renderer in list(_LIVE_RENDERERS):
        renderer.close()
    if _shared_context is not None:
        gl_thread().call(_shared_context.free)
        _shared_context = None


def shared_gl_context() -> Any:
    """The OpenGL context every renderer shares, opened on the GL thread (call it there).

    One context rather than one per environment: on Mesa, switching contexts costs more than
    rendering a frame, and each new context compiles its shaders again.
    """
    global _shared_context
    if not gl_thread().is_current:
        raise RuntimeError("the shared OpenGL context lives on the GL thread: use gl_thread().call")
    if _shared_context is None:
        _shared_context = open_gl_context(_NOMINAL_SIZE, _NOMINAL_SIZE)
        # Registered after the backend's own exit hook (which closes the display), so it runs
        # first: contexts are freed while the display still exists.
        atexit.register(_close_everything)
    return _shared_context


def eye_scene_option(extra_groups: tuple[int, ...] = ()) -> mujoco.MjvOption:
    """Visualisation options that show only the given geom groups (eye view by default)."""
    option = mujoco.MjvOption()
    option.geomgroup[:] = 0
    for group in EYE_GEOM_GROUPS + tuple(extra_groups):
        option.geomgroup[group] = 1
    return option


class SceneRenderer:
    """Renders fixed or free cameras of one model into uint8 RGB arrays, reusing its contexts.

    Usable from any thread: the OpenGL work runs on :func:`gl_thread`."""

    def __init__(self, model: mujoco.MjModel, max_geom: int = 200):
        self._context: mujoco.MjrContext | None = None
        self._model = model
        self._max_width = int(model.vis.global_.offwidth)
        self._max_height = int(model.vis.global_.offheight)
        self._gl_thread = gl_thread()
        self._gl_thread.call(self._open, max_geom)

    def _open(self, max_geom: int) -> None:
        model = self._model
        self._gl = shared_gl_context()
        self._gl.make_current()
        try:
            self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100.value)
        except mujoco.FatalError as error:  # e.g. glfw without a display "opens" no real context
            raise RuntimeError(
                f"MUJOCO_GL={gl_backend()}: MuJoCo found no usable OpenGL context "
                f"({error}); {INSTALL_HINT}"
            ) from error
        self._scene = mujoco.MjvScene(model, maxgeom=max_geom)
        self._perturb = mujoco.MjvPerturb()
        _LIVE_RENDERERS.add(self)

    def upload_texture(self, texture_id: int) -> None:
        """Send a texture's pixels (changed in ``model.tex_data``) to the GPU side."""
        self._gl_thread.call(self._upload_texture, texture_id)

    def _upload_texture(self, texture_id: int) -> None:
        self._make_current()
        mujoco.mjr_uploadTexture(self._model, self._context, texture_id)

    def render(
        self,
        data: mujoco.MjData,
        camera: mujoco.MjvCamera,
        width: int,
        height: int,
        option: mujoco.MjvOption,
        skybox: bool = False,
    ) -> np.ndarray:
        """One RGB frame (height, width, 3) uint8, top row first."""
        if width > self._max_width or height > self._max_height:
            raise ValueError(
                f"image {width}x{height} exceeds the offscreen buffer "
                f"{self._max_width}x{self._max_height}"
            )
        return self._gl_thread.call(self._render, data, camera, width, height, option, skybox)

    def _render(
        self,
        data: mujoco.MjData,
        camera: mujoco.MjvCamera,
        width: int,
        height: int,
        option: mujoco.MjvOption,
        skybox: bool,
    ) -> np.ndarray:
        self._make_current()
        mujoco.mjv_updateScene(
            self._model,
            data,
            option,
            self._perturb,
            camera,
            mujoco.mjtCatBit.mjCAT_ALL,
            self._scene,
        )
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = skybox
        viewport = mujoco.MjrRect(0, 0, width, height)
        mujoco.mjr_render(viewport, self._scene, self._context)
        pixels = np.empty((height, width, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(pixels, None, viewport, self._context)
        # OpenGL's rows start at the bottom.
        return np.ascontiguousarray(pixels[::-1])

    def _make_current(self) -> None:
        if self._context is None:
            raise RuntimeError("this renderer was closed")
        self._gl.make_current()
        # Several MuJoCo contexts share the OpenGL context: bind this one's offscreen framebuffer.
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._context)

    def close(self) -> None:
        """Free this renderer's OpenGL objects (idempotent); the shared context stays."""
        if self._context is not None:
            self._gl_thread.call(self._close)

    def _close(self) -> None:
        if self._context is not None:
            self._gl.make_current()
            self._context.free()
            self._context = None

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # interpreter shutdown or another thread: the GL side may be gone
            pass


def fixed_camera(camera_id: int) -> mujoco.MjvCamera:
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
    camera.fixedcamid = camera_id
    return camera
