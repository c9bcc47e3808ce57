"""The HOAP-3 world's physics: robot, stimulus panel, left-eye camera (paper §3.2, §4.1, §5).

`Physics` reads and sets the quantities of the paper's set-up by name — the head pan α (deg),
the lateral position l of the body (m), the stimulus texture and its distance d (m) — solves the
target pan α* from the model's kinematics, and renders the left-eye image I(t) with the §5
perturbations (camera rotation, Gaussian blur) applied.

Conventions: the robot faces +x; a lateral position l > 0 puts the body l metres to its right
(pick and place, §4.1); a positive pan turns the head to the left, towards the panel, so
α* > 0 for l > 0. The panel's centre lies on the left eye's line of sight at l0 = 0, d metres
ahead of the eye, so α* = 0 at l0.

α* versus atan(l/d): the eye sits e = 0.065 m in front of the pan axis and b = 0.03 m to its left.
Writing v = (d + e, b + l) for the panel centre seen from the pan axis, the eye's line of sight
passes through the centre when  |v| sin(atan2(v_y, v_x) − α*) = b,  i.e. very nearly
α* = atan(l / (d + e)): the eye turns about a point e behind it, so the effective distance is
d + e. At d = 3 m, l = 20 cm α* = 3.732° against atan(l/d) = 3.814° (0.08°, more than one
0.05° action); at 10 m, 5 cm 0.2846° against 0.2865°. The solver below does not use this formula:
it finds the pan at which the (possibly rotated) left camera's optical axis meets the panel centre
in the horizontal direction, by Newton steps on the model's forward kinematics.
"""

from __future__ import annotations

import math
from pathlib import Path
from string import Template

import cv2
import mujoco
import numpy as np
from dm_control import mujoco as dm_mujoco

from parallax.envs import rendering
from parallax.envs.settings import (
    PERIPHERY_SUBSAMPLE,
    ROTATION_AXES,
    DistanceGridConfig,
    EnvConfig,
)
from parallax.envs.stimuli import StimulusSet, background_image
from parallax.geometry import FOCAL_LENGTH_PX

_XML_PATH = Path(__file__).with_name("hoap3.xml")

#: Pan joint limits (deg), HOAP-3's head yaw range.
PAN_LIMIT_DEG = 60.0
#: Left eye relative to the pan axis at pan 0 (m): forward, to the left, and height above ground.
EYE_FORWARD_M = 0.065
EYE_LEFT_M = 0.03
EYE_HEIGHT_M = 0.607
#: Side of the square stimulus panel (m): covers the 150×150 fine window at 10 m with room for a
#: 20 cm lateral move at pan 0 (150/2 + 531·0.2/10 px ≈ 86 px from the centre; 1.65 m ≈ 88 px).
PANEL_SIDE_M = 3.3
#: Geom group of the marker disc at the panel centre (hidden from the eye unless asked for).
MARKER_GROUP = 4
#: Geom groups the side view adds to the eye's: the robot's body and the floor.
ROBOT_GROUP = 1
FLOOR_GROUP = 3


def eye_fovy_deg(image_size: int, focal_px: float = FOCAL_LENGTH_PX) -> float:
    """Vertical field of view giving focal length ``focal_px`` on a square ``image_size`` image."""
    return math.degrees(2.0 * math.atan(image_size / (2.0 * focal_px)))


def model_xml(image_size: int, texture_size: int, max_distance_m: float) -> str:
    """The MJCF of the world for an eye image of ``image_size`` px and panels up to
    ``max_distance_m``."""
    background_x = EYE_FORWARD_M + max_distance_m + 3.0
    # Wide enough for ±25° of view beyond the panel; it sinks below the floor, which hides it there.
    background_half_width = background_x * math.tan(math.radians(40.0))
    background_half_height = background_half_width * 0.75
    values = {
        "offscreen_width": max(image_size, 800),
        "offscreen_height": max(image_size, 600),
        "far_clip": round(4.0 * background_x, 3),
        "eye_fovy": repr(eye_fovy_deg(image_size)),
        "stimulus_texture_size": texture_size,
        "background_texture_width": 512,
        "background_texture_height": 384,
        "floor_half_size": round(background_x + 5.0, 3),
        "panel_half_size": PANEL_SIDE_M / 2,
        "background_x": round(background_x, 6),
        "background_half_width": round(background_half_width, 6),
        "background_half_height": round(background_half_height, 6),
    }
    return Template(_XML_PATH.read_text()).substitute(values)


def _rotation_quat(axis: tuple[float, float, float], angle_deg: float) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, np.asarray(axis, dtype=np.float64), math.radians(angle_deg))
    return quat


def camera_axis(rotation_axis: str | tuple[float, float, float]) -> tuple[float, float, float]:
    """A perturbation rotation axis by name (optical, horizontal, vertical) or as a camera-frame
    vector (perturbation.rotation_axis, checked by parallax.config), as a unit vector."""
    if isinstance(rotation_axis, str):
        return ROTATION_AXES[rotation_axis]
    vector = np.asarray(rotation_axis, dtype=np.float64).reshape(-1)
    return tuple(float(v) for v in vector / np.linalg.norm(vector))


def check_distance(distance_m: float) -> float:
    """A panel distance asked for at run time, as a float: a finite number of metres > 0."""
    if (
        isinstance(distance_m, bool)
        or not isinstance(distance_m, (int, float, np.integer, np.floating))
        or not (math.isfinite(distance_m) and distance_m > 0)
    ):
        raise ValueError(f"distance must be a positive finite number of metres, got {distance_m!r}")
    return float(distance_m)


def _check_finite(name: str, value: float) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not math.isfinite(value)
    ):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


class Physics(dm_mujoco.Physics):
    """The HOAP-3 lateral-pursuit world with named accessors (degrees and metres)."""

    # --- construction ----------------------------------------------------------------------
    @classmethod
    def create(
        cls,
        stimuli: StimulusSet,
        image_size: int = EnvConfig.image_size,
        max_distance_m: float = DistanceGridConfig.stop,
        fovea_px: int | None = EnvConfig.fovea_px,
    ) -> Physics:
        """Compile the world for ``image_size`` eye images (env.image_size, whose range
        parallax.config checks) and attach the (shared) stimulus set; ``fovea_px``
        (env.fovea_px): render only the central square of that side at full resolution."""
        physics = cls.from_xml_string(
            model_xml(int(image_size), stimuli.resolution, max_distance_m)
        )
        physics._setup(stimuli, int(image_size), fovea_px)
        return physics

    def _setup(self, stimuli: StimulusSet, image_size: int, fovea_px: int | None = None) -> None:
        model = self.model.ptr
        self._stimuli = stimuli
        self._image_size = image_size
        self._fovea_px = None if fovea_px is None else int(fovea_px)
        self._renderer: rendering.SceneRenderer | None = None
        self._eye_option = rendering.eye_scene_option()
        self._pan_joint = self.model.name2id("head_pan", "joint")
        self._pan_qpos = int(model.jnt_qposadr[self._pan_joint])
        self._pan_dof = int(model.jnt_dofadr[self._pan_joint])
        self._robot_mocap = int(model.body_mocapid[self.model.name2id("robot", "body")])
        self._stimulus_mocap = int(model.body_mocapid[self.model.name2id("stimulus", "body")])
        self._panel_geom = self.model.name2id("panel", "geom")
        self._marker_geom = self.model.name2id("fixation_marker", "geom")
        self._left_eye = self.model.name2id("left_eye", "camera")
        self._left_eye_camera = rendering.fixed_camera(self._left_eye)
        self._left_eye_quat = model.cam_quat[self._left_eye].copy()
        self._stimulus_texture = self.model.name2id("stimulus", "texture")
        self._scratch = mujoco.MjData(model)  # for the target-pan solver, leaves the state alone
        self._rotation_axis = ROTATION_AXES["optical"]
        self._rotation_deg = 0.0
        self._blur_sigma = 0.0
        self._texture_index = -1
        self._distance = float("nan")
        self._write_texture("background", background_image(512, 384))
        self.set_stimulus(0, 3.0)

    # --- the world is kinematic --------------------------------------------------------------
    def step(self, nstep: int = 1) -> None:
        """Advance time only: the body is placed and the eye turned exactly (paper §3: perfect
        control)."""
        self.data.time += nstep * self.model.opt.timestep
        self.forward()

    # --- named accessors ---------------------------------------------------------------------
    @property
    def image_size(self) -> int:
        return self._image_size

    @property
    def stimuli(self) -> StimulusSet:
        return self._stimuli

    def pan_deg(self) -> float:
        """Head pan α in degrees (positive: to the left)."""
        return math.degrees(float(self.data.qpos[self._pan_qpos]))

    def set_pan_deg(self, pan_deg: float) -> float:
        """Turn the head to ``pan_deg`` degrees, clipped to ±60°; returns the pan set."""
        pan = float(np.clip(_check_finite("pan", pan_deg), -PAN_LIMIT_DEG, PAN_LIMIT_DEG))
        self.data.qpos[self._pan_qpos] = math.radians(pan)
        self.data.qvel[self._pan_dof] = 0.0
        self.forward()
        return pan

    def lateral_position(self) -> float:
        """Lateral position l of the body in metres (positive: to the robot's right)."""
        return -float(self.data.mocap_pos[self._robot_mocap, 1])

    def set_lateral_position(self, lateral_m: float) -> None:
        """Pick up the robot and put it down ``lateral_m`` metres to the right of l0 (§4.1)."""
        self.data.mocap_pos[self._robot_mocap, 1] = -_check_finite("lateral position", lateral_m)
        self.forward()

    def forward_position(self) -> float:
        """How far the body has walked towards the panel from its place in the sweep (m)."""
        return float(self.data.mocap_pos[self._robot_mocap, 0])

    def set_forward_position(self, forward_m: float) -> None:
        """Put the body ``forward_m`` metres ahead (towards the panel) of its place in the sweep;
        the kinematics (not the rest of mj_forward) are recomputed, which is all that the walk's
        touch query (parallax.envs.walk) reads."""
        self.data.mocap_pos[self._robot_mocap, 0] = _check_finite("forward position", forward_m)
        mujoco.mj_kinematics(self.model.ptr, self.data.ptr)

    def distance(self) -> float:
        """Distance d (m) from the left eye at l0 to the panel."""
        return self._distance

    def texture_index(self) -> int:
        return self._texture_index

    def set_stimulus(self, texture_index: int, distance_m: float) -> None:
        """Show texture ``texture_index`` on the panel, ``distance_m`` metres ahead of the eye at
        l0."""
        count = self._stimuli.count
        if (
            isinstance(texture_index, bool)
            or not isinstance(texture_index, (int, np.integer))
            or not 0 <= texture_index < count
        ):
            raise ValueError(
                f"texture index {texture_index!r} is out of range: "
                f"{count} textures (0..{count - 1})"
            )
        distance_m = check_distance(distance_m)
        if int(texture_index) != self._texture_index:
            self._write_texture("stimulus", self._stimuli.textures[int(texture_index)])
            self._texture_index = int(texture_index)
        self.data.mocap_pos[self._stimulus_mocap] = (
            EYE_FORWARD_M + distance_m,
            EYE_LEFT_M,
            EYE_HEIGHT_M,
        )
        self._distance = distance_m
        self.forward()

    def _write_texture(self, name: str, rgb: np.ndarray) -> None:
        model = self.model.ptr
        texture_id = self.model.name2id(name, "texture")
        height, width = int(model.tex_height[texture_id]), int(model.tex_width[texture_id])
        channels = int(model.tex_nchannel[texture_id])
        if rgb.shape != (height, width, 3) or channels != 3:
            raise ValueError(
                f"texture {name!r} expects {height}x{width}x{channels} pixels, got {rgb.shape}"
            )
        start = int(model.tex_adr[texture_id])
        # Row 0 is the top of the panel as the robot sees it (the panel's xyaxes make it so).
        model.tex_data[start : start + rgb.size] = np.ascontiguousarray(rgb).reshape(-1)
        if self._renderer is not None:
            self._renderer.upload_texture(texture_id)

    # --- ground truth ------------------------------------------------------------------------
    def target_pan_deg(self) -> float:
        """α*: the pan at which the left eye's optical axis meets the panel centre (horizontally).

        Solved by Newton steps on the forward kinematics of a scratch copy of the state, so it
        follows whatever the model says (pan-axis offset, eye offset, a rotated camera).
        """
        scratch = self._scratch
        scratch.qpos[:] = self.data.qpos
        scratch.mocap_pos[:] = self.data.mocap_pos
        scratch.mocap_quat[:] = self.data.mocap_quat
        model = self.model.ptr
        pan = math.atan2(self.lateral_position(), self._distance + EYE_FORWARD_M)
        step = 1e-6
        for _ in range(20):
            error = self._horizontal_bearing(model, scratch, pan)
            slope = (self._horizontal_bearing(model, scratch, pan + step) - error) / step
            update = error / slope
            pan -= update
            if abs(update) < 1e-13:
                break
        return math.degrees(pan)

    def _horizontal_bearing(
        self, model: mujoco.MjModel, scratch: mujoco.MjData, pan_rad: float
    ) -> float:
        """Angle of the panel centre from the camera's vertical mid-plane, at pan ``pan_rad``."""
        scratch.qpos[self._pan_qpos] = pan_rad
        mujoco.mj_kinematics(model, scratch)
        mujoco.mj_camlight(model, scratch)
        offset = scratch.geom_xpos[self._panel_geom] - scratch.cam_xpos[self._left_eye]
        in_camera = scratch.cam_xmat[self._left_eye].reshape(3, 3).T @ offset
        return math.atan2(in_camera[0], -in_camera[2])

    def project_to_left_eye(self, point: np.ndarray) -> np.ndarray:
        """Pixel (column, row) of a world point in the left-eye image (pixel centres at
        integers)."""
        offset = np.asarray(point, dtype=np.float64) - self.data.cam_xpos[self._left_eye]
        x, y, z = self.data.cam_xmat[self._left_eye].reshape(3, 3).T @ offset
        centre = (self._image_size - 1) / 2.0
        return np.array([centre + FOCAL_LENGTH_PX * x / -z, centre - FOCAL_LENGTH_PX * y / -z])

    def panel_centre(self) -> np.ndarray:
        return self.data.geom_xpos[self._panel_geom].copy()

    # --- perturbations (§5) --------------------------------------------------------------------
    def set_perturbation(
        self,
        camera_rotation_deg: float | None = None,
        blur_sigma: float | None = None,
        rotation_axis: str | tuple[float, float, float] | None = None,
    ) -> None:
        """Rotate the left camera and/or blur captured images, at once and without recompiling.

        The rotation changes ``model.cam_quat``; a positive angle about the optical axis turns the
        camera clockwise as seen from behind it, so the image content turns counter-clockwise.
        The blur (σ in pixels) applies to every image captured from now on, I0 included.
        """
        if blur_sigma is not None:
            self._blur_sigma = float(blur_sigma)
        if rotation_axis is not None:
            self._rotation_axis = camera_axis(rotation_axis)
        if camera_rotation_deg is not None:
            self._rotation_deg = float(camera_rotation_deg)
        quat = np.zeros(4)
        mujoco.mju_mulQuat(
            quat, self._left_eye_quat, _rotation_quat(self._rotation_axis, self._rotation_deg)
        )
        self.model.ptr.cam_quat[self._left_eye] = quat
        self.forward()

    @property
    def perturbation(self) -> dict[str, object]:
        return {
            "camera_rotation_deg": self._rotation_deg,
            "rotation_axis": self._rotation_axis,
            "blur_sigma": self._blur_sigma,
        }

    # --- rendering -----------------------------------------------------------------------------
    @property
    def renderer(self) -> rendering.SceneRenderer:
        if self._renderer is None:
            self._renderer = rendering.SceneRenderer(self.model.ptr)
        return self._renderer

    def render_left_eye(self, show_marker: bool = False) -> np.ndarray:
        """The left-eye image I(t): (S, S, 3) uint8, perturbation blur applied."""
        option = rendering.eye_scene_option((MARKER_GROUP,)) if show_marker else self._eye_option
        if self._fovea_px is None:
            image = self.renderer.render(
                self.data.ptr, self._left_eye_camera, self._image_size, self._image_size, option
            )
        else:
            image = self._render_fovea_and_periphery(option)
        if self._blur_sigma > 0:
            image = cv2.GaussianBlur(
                image,
                (0, 0),
                sigmaX=self._blur_sigma,
                sigmaY=self._blur_sigma,
                borderType=cv2.BORDER_REFLECT_101,
            )
        return image

    def _render_fovea_and_periphery(self, option: mujoco.MjvOption) -> np.ndarray:
        """The eye image with only its central ``fovea_px`` square at full resolution (a camera
        whose field of view is that square's: the full render's centre, to one grey level), the
        rest rendered at 1/PERIPHERY_SUBSAMPLE of the resolution and enlarged by repeating its
        pixels: what the retina reads (the fine scale's window at full resolution, the coarse
        scale's after a ×8 pyramid)."""
        size, fovea, factor = self._image_size, self._fovea_px, PERIPHERY_SUBSAMPLE
        periphery = self.renderer.render(
            self.data.ptr, self._left_eye_camera, size // factor, size // factor, option
        )
        # nearest-neighbour at a whole factor: every pixel becomes a factor×factor block
        image = cv2.resize(periphery, (size, size), interpolation=cv2.INTER_NEAREST)
        fovy = self.model.cam_fovy[self._left_eye].copy()
        self.model.cam_fovy[self._left_eye] = eye_fovy_deg(fovea)
        try:
            centre = self.renderer.render(
                self.data.ptr, self._left_eye_camera, fovea, fovea, option
            )
        finally:
            self.model.cam_fovy[self._left_eye] = fovy
        margin = (size - fovea) // 2
        image[margin : margin + fovea, margin : margin + fovea] = centre
        return image

    def render_view(
        self,
        camera: mujoco.MjvCamera,
        width: int,
        height: int,
        groups: tuple[int, ...] = (ROBOT_GROUP, FLOOR_GROUP),
    ) -> np.ndarray:
        """Any camera (e.g. a free side view) with the eye's groups plus ``groups`` and the sky."""
        return self.renderer.render(
            self.data.ptr, camera, width, height, rendering.eye_scene_option(groups), skybox=True
        )

    def close_renderer(self) -> None:
        """Free the OpenGL resources now (they are re-created on the next render)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
