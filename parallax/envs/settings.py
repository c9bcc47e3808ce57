"""The world's settings (env.*, perturbation.*; paper §3.2, §4.1, §5) beside their checks.

Every setting of the world as a typed dataclass field with its one default, the sizes and
choices it allows, and the checks of the values a type cannot rule out (parallax.checks); the
body's walk (env.walk, beyond the paper) with the presentation of its growth spurt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from parallax.checks import Checks
from parallax.envs.sweep import (
    MOTIONS,
    SWEEP_PROFILES,
    fastest_followable_speed_m,
    fastest_target_pan_deg,
)

#: With env.fovea_px, the image outside the fovea is rendered at 1/this of the resolution.
PERIPHERY_SUBSAMPLE = 4
#: The eye image sizes the world can render (parallax.envs.hoap3.Physics.create).
IMAGE_SIZES = (16, 2048)
#: Camera axes for the perturbation rotation, in the camera's frame (it looks along its −z).
ROTATION_AXES = {
    "optical": (0.0, 0.0, -1.0),
    "horizontal": (1.0, 0.0, 0.0),
    "vertical": (0.0, 1.0, 0.0),
}
#: The choices of env.stimuli.source, .split and .kind.
SOURCES = ("skimage", "dir", "procedural")
SPLITS = ("train", "heldout")
PROCEDURAL_KINDS = ("dead_leaves", "pink_noise")
#: The texture sides the panel takes (texels).
RESOLUTIONS = (8, 4096)


@dataclass
class DistanceGridConfig:
    """Panel distances drawn per presentation, metres: start, start + step, …, stop (§4.1)."""

    #: Nearest panel distance (m).
    start: float = 3.0
    #: Farthest panel distance (m).
    stop: float = 10.0
    #: Spacing of the distances (m).
    step: float = 0.1


@dataclass
class StimuliConfig:
    """The panel's textures, "a set of 100 different images" (§4.1); parallax.envs.stimuli."""

    #: skimage: crops of the photographs scikit-image ships | dir: your own images (``dir``) |
    #: procedural: generated textures (``kind``), an ablation.
    source: str = "skimage"
    #: train | heldout: held-out crops come from other photographs (a folder is used whole).
    split: str = "train"
    #: Number of textures; null: 120 train / 40 held-out, or every readable image of ``dir``.
    count: int | None = None
    #: Folder of your own images; setting it switches ``source`` to dir.
    dir: str | None = None
    #: Texture side in texels.
    resolution: int = 256
    #: Seed of the crop positions / procedural textures (not of the presentation order).
    seed: int = 0
    #: Procedural kind: dead_leaves | pink_noise.
    kind: str = "dead_leaves"


@dataclass
class SweepConfig:
    """Beyond the paper: the body's continuous sweep from l0 to the end of L in one trial
    (``env.motion=continuous``; parallax.envs.sweep)."""

    #: Mean lateral speed, metres per iteration (0.002: 5–20 cm in 101 iterations).
    speed_m: float = 0.002
    #: constant | smooth: a minimum-jerk path, still at both ends (peak speed 1.875× the mean).
    profile: str = "constant"


@dataclass
class WalkConfig:
    """Beyond the paper (its second future work, §7): the body's walk straight to the panel after
    a presentation's lateral sweep, until its left hand touches it (parallax.envs.walk). Only
    runs with distance.targets=odometry walk. These are the body's true values; what the robot
    believes its stride to be is distance.odometry.nominal_stride_m."""

    #: The body's true stride length (m).
    stride_m: float = 0.05
    #: Each stride's length varies by this fraction (sd of a Gaussian factor 1 + slip·N(0, 1)).
    stride_slip: float = 0.0
    #: The stride that ends in touch is retaken in this many equal parts, so the robot also knows
    #: how far into its last stride the touch came (odometry resolution stride_m / substeps).
    substeps: int = 10
    #: A growth spurt: the true stride is multiplied by this from ``growth_start_fraction`` of
    #: train.presentations on, while the robot keeps its nominal stride (1: no spurt).
    growth_factor: float = 1.0
    #: Fraction of train.presentations after which the spurt happens; null: never.
    growth_start_fraction: float | None = None


@dataclass
class EnvConfig:
    """The world (§4.1): HOAP-3-like humanoid, textured panel, still background, in MuJoCo.

    The keyword arguments of ``parallax.envs.load``, which reads its defaults here (``robots``,
    ``robots_per_turn`` and ``walk`` aside: parallax.parts.NOT_THE_WORLDS);
    the lateral list L comes from ``curriculum`` and the perturbation from ``perturbation``.
    """

    #: Side of the square left-eye image in pixels; the focal length stays 531 px (Table 1).
    image_size: int = 256
    #: null: every pixel of the eye image is rendered at full resolution. A size (the fine
    #: scale's window, 150): only what the retina reads at full resolution, the central square of
    #: this many pixels, and the rest of the image rendered at 1/4 of the resolution and
    #: enlarged, which the coarse scale's ×8 pyramid reads (fewer pixels to rasterise; it changes
    #: the images, so it is off by default; docs/performance.md).
    fovea_px: int | None = None
    #: t_h, iterations (eye movements) per lateral position (§4.1).
    trial_length: int = 30
    #: The paper's distances 3.0, 3.1, …, 10.0 m (§4.1).
    distances: DistanceGridConfig = field(default_factory=DistanceGridConfig)
    #: At each new lateral position: true turns the pan back to 0 (§3.2), false keeps it.
    pan_reset: bool = True
    #: Beyond the paper: each trial starts from a pan drawn uniformly in ±this many degrees
    #: instead of 0, so the eye also learns from the far side of the target (0: the paper, and
    #: the recipe at multiple lateral positions; the single-position files use 2).
    initial_pan_jitter_deg: float = 0.0
    #: Largest pan increment the world accepts, degrees (A = {±0.2, ±0.1, ±0.05, 0}, §3.4).
    max_pan_increment_deg: float = 0.2
    #: pick_and_place: the body is set down at each position of L for t_h iterations (§4.1) |
    #: continuous: it sweeps from l0 to the end of L in one trial while the eye acts (``sweep``;
    #: beyond the paper), and q_p is the pan as it passes l_p.
    motion: str = "pick_and_place"
    sweep: SweepConfig = field(default_factory=SweepConfig)
    stimuli: StimuliConfig = field(default_factory=StimuliConfig)
    #: B robots in lockstep, each with its own stimulus, distance and pan; one coder and policy
    #: call serves all of them (beyond the paper, for speed; B = 1 is the paper's single robot).
    robots: int = 1
    #: B robots take their turns in groups of this many (0: all B in one turn): each turn's
    #: policy update and action come after the previous turn's, and its worlds render while the
    #: later turns are encoded and act (beyond the paper; B ≤ this is one turn, the paper's order).
    robots_per_turn: int = 4
    walk: WalkConfig = field(default_factory=WalkConfig)


@dataclass
class PerturbationConfig:
    """The robustness test of §5: the left camera rotated and its images blurred while training
    goes on."""

    #: Rotation of the left camera in degrees (§5: 15).
    camera_rotation_deg: float = 0.0
    #: optical | horizontal | vertical, or a 3-vector in the camera frame.
    rotation_axis: Any = "optical"
    #: σ of the Gaussian blur in pixels (§5: 2).
    blur_sigma: float = 0.0
    #: Fraction of train.presentations after which the perturbation is switched on; null: never.
    start_fraction: float | None = None


def check_env(check: Checks) -> None:
    low, high = IMAGE_SIZES
    size = check.integer("env.image_size", low, " (pixels)")
    if size > high:
        check.fail("env.image_size", size, f"must be at most {high} pixels")
    if check.get("env.fovea_px") is not None:
        fovea = check.integer("env.fovea_px", 2, " (pixels) or null")
        if fovea > size or (size - fovea) % 2 or size % PERIPHERY_SUBSAMPLE:
            check.fail(
                "env.fovea_px",
                fovea,
                f"must be at most env.image_size={size}, with an even margin, in an image whose "
                f"side is a multiple of {PERIPHERY_SUBSAMPLE}",
            )
    check.integer("env.trial_length", 2, " (iterations per lateral position)")
    start = check.number("env.distances.start", above=0, what=" (metres)")
    stop = check.number("env.distances.stop", above=0, what=" (metres)")
    check.number("env.distances.step", above=0, what=" (metres)")
    if stop < start:
        check.fail("env.distances.start", start, f"must not exceed env.distances.stop={stop:g}")
    check.number("env.initial_pan_jitter_deg", at_least=0, below=90, what=" (degrees)")
    check.number("env.max_pan_increment_deg", above=0, below=90, what=" (degrees)")
    check.integer("env.robots", 1)
    check.integer("env.robots_per_turn", 0, " (robots; 0: all in one turn)")


def check_perturbation(check: Checks) -> None:
    rotation = check.number("perturbation.camera_rotation_deg", what=" (degrees)")
    blur = check.number("perturbation.blur_sigma", at_least=0, what=" (pixels)")
    axis = check.get("perturbation.rotation_axis")
    if isinstance(axis, str):
        check.choice("perturbation.rotation_axis", sorted(ROTATION_AXES))
    elif not (
        isinstance(axis, list)
        and len(axis) == 3
        and all(isinstance(v, (int, float)) and math.isfinite(v) for v in axis)
        and any(v != 0 for v in axis)
    ):
        check.fail(
            "perturbation.rotation_axis",
            axis,
            f"must be one of {', '.join(sorted(ROTATION_AXES))} or a non-zero 3-vector",
        )
    start = check.optional_number("perturbation.start_fraction", at_least=0, at_most=1)
    if start is None and (rotation != 0 or blur != 0):
        check.fail(
            "perturbation.start_fraction",
            None,
            f"the perturbation (camera_rotation_deg={rotation:g}, blur_sigma={blur:g}) would "
            "never be switched on; give a fraction of train.presentations, or perturbation=none",
        )
    if start is not None and rotation == 0 and blur == 0:
        # it would still keep a checkpoint and a summary "before" a perturbation that never comes
        check.fail(
            "perturbation.start_fraction",
            start,
            "switches on a perturbation that changes nothing (camera_rotation_deg=0, "
            "blur_sigma=0); set it to null, or choose perturbation=rotate_blur",
        )


def check_walk(check: Checks) -> None:
    check.number("env.walk.stride_m", above=0, what=" (metres)")
    check.number("env.walk.stride_slip", at_least=0, below=0.5)
    check.integer("env.walk.substeps", 1)
    check.number("env.walk.growth_factor", above=0)
    start = check.optional_number("env.walk.growth_start_fraction", at_least=0, at_most=1)
    if start is not None and check.get("distance.targets") != "odometry":
        check.fail(
            "env.walk.growth_start_fraction",
            start,
            "a growth spurt needs walks: set distance.targets=odometry, or leave it null",
        )


def check_motion(check: Checks) -> None:

    motion = check.choice("env.motion", MOTIONS)
    speed = check.number("env.sweep.speed_m", above=0, what=" (metres per iteration)")
    profile = check.choice("env.sweep.profile", SWEEP_PROFILES)
    if motion != "continuous":
        return
    check.require("movement.route", "list", "env.motion=continuous sweeps L")
    check.require(
        "train.distance_readout",
        "last",
        "env.motion=continuous has one trial a presentation: q_p is the pan at l_p (last)",
    )
    # the eye must be able to keep up with the target where it turns fastest
    nearest = float(check.get("env.distances.start"))
    step = max(abs(float(a)) for a in check.get("policy.actions"))
    if fastest_target_pan_deg(speed, profile, nearest) > step + 1e-12:
        check.fail(
            "env.sweep.speed_m",
            speed,
            f"the target's pan turns up to {fastest_target_pan_deg(speed, profile, nearest):.3g}° "
            f"an iteration at {nearest:g} m ({profile} profile), faster than the eye's largest "
            f"step {step:g}°: at most {fastest_followable_speed_m(step, profile, nearest):.4g} m",
        )


def check_stimuli(check: Checks) -> None:
    """The values of env.stimuli (whether they give textures: parallax.envs.stimuli.
    check_loadable)."""
    source = check.choice("env.stimuli.source", SOURCES)
    check.choice("env.stimuli.split", SPLITS)
    check.choice("env.stimuli.kind", PROCEDURAL_KINDS)
    low, high = RESOLUTIONS
    resolution = check.integer("env.stimuli.resolution", low, " (texels)")
    if resolution > high:
        check.fail("env.stimuli.resolution", resolution, f"must be at most {high} texels")
    check.integer("env.stimuli.seed", 0)
    if check.get("env.stimuli.count") is not None:
        check.integer("env.stimuli.count", 1, " or null (all)")
    folder = check.get("env.stimuli.dir")
    if folder is not None and source == "procedural":
        check.fail(
            "env.stimuli.dir",
            folder,
            "is set but env.stimuli.source is procedural; set env.stimuli.dir=null or "
            "env.stimuli.source=dir",
        )
    if source == "dir" and not folder:
        check.fail("env.stimuli.dir", folder, "env.stimuli.source=dir needs a folder of images")


def growth_start(cfg) -> int | None:
    """Presentation index from which the body's grown stride is used (None: never): the one place
    ``env.walk.growth_start_fraction`` becomes a presentation (the trainer and parallax-replay)."""
    fraction = cfg["env"]["walk"]["growth_start_fraction"]  # a DictConfig or a plain dict
    if fraction is None:
        return None
    return int(round(float(fraction) * int(cfg["train"]["presentations"])))
