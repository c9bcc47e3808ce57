"""Headless OpenGL rendering of the robot's eye (paper §3.2: the left-eye image I(t)).

A small renderer that keeps one MuJoCo render context and one scene per physics, in one OpenGL
context per thread shared by all environments, so a 256×256 eye frame costs about a millisecond
on a CPU (Mesa) — dm_control's generic ``physics.render`` re-creates its camera and scene on
every call and opens one OpenGL context per physics. It also re-uploads a texture after its
pixels changed, which is how the stimulus is swapped without recompiling.

Backend: see ``parallax.envs.backend`` (the user's ``MUJOCO_GL``, egl by default, one clear
error when it cannot render).
"""

from __future__ import annotations

import atexit
import threading
import weakref
from typing import Any

import numpy as np

from parallax.envs.backend import INSTALL_HINT, gl_backend, import_mujoco, open_gl_context

mujoco = import_mujoco()

#: Geom groups the eye sees: panel (0) and background (2); the robot's body (1) is behind the
#: eyes, the floor (3) is for the side view, markers (4) for tests and pictures.
EYE_GEOM_GROUPS = (0, 2)


#: Nominal size of the shared contexts: each MuJoCo render context has its own offscreen framebuffer.
_NOMINAL_SIZE = 2048

_LIVE_RENDERERS: "weakref.WeakSet[SceneRenderer]" = weakref.WeakSet()
_SHARED_CONTEXTS: dict[int, Any] = {}


def _close_everything() -> None:
    for renderer in list(_LIVE_RENDERERS):
        renderer.close()
    for context in _SHARED_CONTEXTS.values():
        context.free()
    _SHARED_CONTEXTS.clear()


def shared_gl_context() -> Any:
    """This thread's OpenGL context, shared by every renderer the thread creates.

    One context per thread rather than one per environment: switching contexts costs more than a
    frame on Mesa (16 environments rendering in turn: 4 ms a frame with a context each, 1.5 ms
    with one), and each new context compiles its shaders again (≈ 0.25 s).
    """
    thread = threading.get_ident()
    if thread not in _SHARED_CONTEXTS:
        context = open_gl_context(_NOMINAL_SIZE, _NOMINAL_SIZE)
        if not _SHARED_CONTEXTS:
            # Registered after the backend's own exit hook (which closes the display), so it runs
            # first: contexts are freed while the display still exists.
            atexit.register(_close_everything)
        _SHARED_CONTEXTS[thread] = context
    return _SHARED_CONTEXTS[thread]


def eye_scene_option(extra_groups: tuple[int, ...] = ()) -> mujoco.MjvOption:
    """Visualisation options that show only the given geom groups (eye view by default)."""
    option = mujoco.MjvOption()
    option.geomgroup[:] = 0
    for group in EYE_GEOM_GROUPS + tuple(extra_groups):
        option.geomgroup[group] = 1
    return option


class SceneRenderer:
    """Renders fixed or free cameras of one model into uint8 RGB arrays, reusing its contexts."""

    def __init__(self, model: mujoco.MjModel, max_geom: int = 200):
        self._context: mujoco.MjrContext | None = None
        self._model = model
        self._max_width = int(model.vis.global_.offwidth)
        self._max_height = int(model.vis.global_.offheight)
        self._gl = shared_gl_context()
        self._gl.make_current()
        try:
            self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100.value)
        except mujoco.FatalError as error:  # e.g. glfw without a display "opens" no real context
            raise RuntimeError(f"MUJOCO_GL={gl_backend()}: MuJoCo found no usable OpenGL context "
                               f"({error}); {INSTALL_HINT}") from error
        self._scene = mujoco.MjvScene(model, maxgeom=max_geom)
        self._perturb = mujoco.MjvPerturb()
        _LIVE_RENDERERS.add(self)

    def upload_texture(self, texture_id: int) -> None:
        """Send a texture's pixels (changed in ``model.tex_data``) to the GPU side."""
        self._make_current()
        mujoco.mjr_uploadTexture(self._model, self._context, texture_id)

    def render(self, data: mujoco.MjData, camera: mujoco.MjvCamera, width: int, height: int,
               option: mujoco.MjvOption, skybox: bool = False) -> np.ndarray:
        """One RGB frame (height, width, 3) uint8, top row first."""
        if width > self._max_width or height > self._max_height:
            raise ValueError(f"image {width}x{height} exceeds the offscreen buffer "
                             f"{self._max_width}x{self._max_height}")
        self._make_current()
        mujoco.mjv_updateScene(self._model, data, option, self._perturb, camera,
                               mujoco.mjtCatBit.mjCAT_ALL, self._scene)
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
        if threading.get_ident() not in _SHARED_CONTEXTS or _SHARED_CONTEXTS[threading.get_ident()] is not self._gl:
            raise RuntimeError("a renderer must be used in the thread that created it")
        self._gl.make_current()
        # Several MuJoCo contexts share the OpenGL context: bind this one's offscreen framebuffer.
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._context)

    def close(self) -> None:
        """Free this renderer's OpenGL objects (idempotent); the shared context stays."""
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
