"""Which OpenGL backend renders the robot's eye (headless: paper §3.2's images without a display).

The user's ``MUJOCO_GL`` (egl, osmesa, glfw) is respected; when unset, ``parallax.envs`` sets it
to egl before MuJoCo is imported (Mesa's EGL on a CPU-only machine, the GPU driver's where there
is one). There is no silent fallback to another backend: if the chosen one cannot be loaded or
cannot open a context, one error names it and says what to install.
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType
from typing import Any

INSTALL_HINT = (
    "install an OpenGL backend MuJoCo can render with: Mesa's EGL on a CPU-only machine "
    "(Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri; conda: mesalib) or the GPU "
    "driver's EGL, with MUJOCO_GL=egl (the default); or OSMesa (apt-get install libosmesa6) "
    "with MUJOCO_GL=osmesa"
)

_BACKEND_MODULES = {"egl": "mujoco.egl", "osmesa": "mujoco.osmesa", "glfw": "mujoco.glfw"}


def default_to_egl() -> None:
    """Set ``MUJOCO_GL=egl`` unless the user chose a backend."""
    os.environ.setdefault("MUJOCO_GL", "egl")


def gl_backend() -> str:
    """The OpenGL backend in use: the user's ``MUJOCO_GL``, egl when unset."""
    return os.environ.get("MUJOCO_GL", "egl").strip().lower() or "egl"


def import_mujoco() -> ModuleType:
    """``import mujoco``, turning a broken GL backend (it is loaded on import) into one clear
    error."""
    try:
        return importlib.import_module("mujoco")
    except (ImportError, OSError, AttributeError, RuntimeError) as error:
        raise RuntimeError(
            f"MUJOCO_GL={gl_backend()}: MuJoCo could not load this OpenGL backend "
            f"({type(error).__name__}: {error}); {INSTALL_HINT}"
        ) from error


def gl_context_class() -> Any:
    """The ``GLContext`` class of the chosen backend."""
    backend = gl_backend()
    if backend not in _BACKEND_MODULES:
        raise RuntimeError(
            f"MUJOCO_GL={backend!r} is not a backend parallax renders with; "
            f"use one of {sorted(_BACKEND_MODULES)}"
        )
    try:
        return importlib.import_module(_BACKEND_MODULES[backend]).GLContext
    except (ImportError, OSError, AttributeError) as error:
        raise RuntimeError(
            f"MUJOCO_GL={backend}: the OpenGL backend could not be loaded "
            f"({type(error).__name__}: {error}); {INSTALL_HINT}"
        ) from error


def open_gl_context(width: int, height: int) -> Any:
    """An offscreen OpenGL context of the chosen backend, made current."""
    context_class = gl_context_class()
    try:
        context = context_class(width, height)
        context.make_current()
    except Exception as error:  # the backends raise assorted GL/ctypes errors; name them all
        raise RuntimeError(
            f"MUJOCO_GL={gl_backend()}: could not open an OpenGL context "
            f"({type(error).__name__}: {error}); {INSTALL_HINT}"
        ) from error
    return context
