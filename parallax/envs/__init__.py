"""The world (paper §3.2, §4.1, §5): a HOAP-3-like humanoid pursuing a textured panel in MuJoCo.

``parallax.envs.load(seed=..., lateral_positions=[...], ...)`` returns a dm_control
``control.Environment`` whose observations carry the reference image I0, the left-eye image I(t),
the pan α and the target pan α* (see ``parallax.envs.task``; the loop reads them as an
``Observation``). The robot, the camera and the
target-pan solver live in ``hoap3``; textures in ``stimuli``; the fast eye renderer in
``rendering``, whose one GL thread (``gl_thread()``) makes every OpenGL call and can step the
worlds while the caller computes.

Rendering is headless: a ``MUJOCO_GL`` the user set is respected, otherwise it defaults to egl
(set here, before dm_control or MuJoCo's GL modules read it).
"""

from parallax.envs.backend import default_to_egl, import_mujoco

default_to_egl()
import_mujoco()  # first, so that a broken GL backend gives one clear error

from parallax.envs.hoap3 import PAN_LIMIT_DEG, Physics, eye_fovy_deg  # noqa: E402
from parallax.envs.observation import Observation  # noqa: E402
from parallax.envs.rendering import gl_thread  # noqa: E402
from parallax.envs.stimuli import StimulusSet, load_stimuli  # noqa: E402
from parallax.envs.task import (  # noqa: E402
    ACTION_SET_DEG,
    LateralPursuitTask,
    PursuitEnvironment,
    distance_grid,
    load,
)

__all__ = [
    "load",
    "Observation",
    "Physics",
    "LateralPursuitTask",
    "PursuitEnvironment",
    "StimulusSet",
    "load_stimuli",
    "distance_grid",
    "eye_fovy_deg",
    "gl_thread",
    "ACTION_SET_DEG",
    "PAN_LIMIT_DEG",
]
