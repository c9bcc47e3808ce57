"""Ranges and cross-field rules of the configuration, checked before anything is built or written.

Hydra checks each value's type against :mod:`parallax.config.schema`; :func:`validate` checks
what a type cannot say: that a number is finite and in range, a choice is one the components
know, lists are non-empty and ordered, and settings that depend on each other agree (a window
fits in the image, every action is a pan increment the world accepts, …). Each failure is a
:class:`ConfigError` naming the first key and value that cannot work, so `parallax-train` can
stop with one line before Hydra creates a run directory, and a sweep's job before the trainer
writes into its directory. The checks are here alone: a component built from a config
trusts its settings, and raises only for what a config cannot say (the shapes of the tensors
it is handed, the arguments of a call at run time, the content of a file).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from omegaconf import DictConfig, OmegaConf

from parallax.config.errors import ConfigError
from parallax.config.plumbing import closest_key, schema_keys
from parallax.config.schema import PERIPHERY_SUBSAMPLE, ROBOT_UPDATES
from parallax.readouts import READOUTS

#: Settings the trainer fills at run time; ``???`` in a composed config.
RUN_TIME_KEYS = frozenset(
    {
        "coder.seed",
        "coder.image_size",
        "policy.state_dim",
        "policy.num_scales",
        "policy.seed",
        "distance.lateral_positions",
        "distance.seed",
    }
)
#: train.resume_from: the latest checkpoint, or the one written before it.
RESUME_FROM = ("latest", "previous")
#: movement.route: the paper's sweep of L, or the route the robot plans (beyond the paper, §7).
ROUTES = ("list", "planned")
#: coder.pairing: the paper's (I0, I(t)), or consecutive images (I(t−1), I(t)).
PAIRINGS = ("reference", "consecutive")
#: The eye image sizes the world can render (parallax.envs.hoap3.Physics.create).
IMAGE_SIZES = (16, 2048)


class _Checks:
    """Reads values from the config by dotted key and raises ConfigError naming that key."""

    def __init__(self, cfg: DictConfig):
        self.cfg = cfg

    def get(self, key: str) -> Any:
        value = OmegaConf.select(self.cfg, key, throw_on_missing=True)
        return OmegaConf.to_container(value) if OmegaConf.is_config(value) else value

    @staticmethod
    def fail(key: str, value: Any, reason: str) -> None:
        raise ConfigError(key, value, reason)

    def integer(self, key: str, minimum: int, what: str = "") -> int:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            self.fail(key, value, f"must be a whole number ≥ {minimum}{what}")
        return value

    def number(
        self,
        key: str,
        above: float | None = None,
        at_least: float | None = None,
        at_most: float | None = None,
        below: float | None = None,
        what: str = "",
    ) -> float:
        """A finite number within the given bounds; ``what`` says what it is, for the message."""
        value = self.get(key)
        bounds = [
            f"> {above:g}" if above is not None else "",
            f"≥ {at_least:g}" if at_least is not None else "",
            f"≤ {at_most:g}" if at_most is not None else "",
            f"< {below:g}" if below is not None else "",
        ]
        needed = " and ".join(b for b in bounds if b)
        reason = f"must be a finite number{' ' + needed if needed else ''}{what}"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, value, reason)
        number = float(value)
        if not math.isfinite(number):
            self.fail(key, value, reason)
        if (above is not None and not number > above) or (
            at_least is not None and not number >= at_least
        ):
            self.fail(key, value, reason)
        if (at_most is not None and not number <= at_most) or (
            below is not None and not number < below
        ):
            self.fail(key, value, reason)
        return number

    def optional_number(self, key: str, **bounds: Any) -> float | None:
        return None if self.get(key) is None else self.number(key, **bounds)

    def choice(self, key: str, options: Sequence[str]) -> str:
        value = self.get(key)
        if value not in options:
            self.fail(key, value, f"must be one of {', '.join(map(str, options))}")
        return value

    def positions(self, key: str, values: Any, what: str) -> list[float]:
        """A non-empty, strictly increasing list of positive finite metres."""
        if not isinstance(values, list) or not values:
            self.fail(key, values, f"{what} must hold at least one lateral position (metres)")
        for value in values:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                self.fail(key, values, f"{what} must hold numbers of metres, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                self.fail(key, values, f"{what} must hold finite lateral steps > 0 m")
        if any(b <= a for a, b in zip(values, values[1:])):
            self.fail(key, values, f"{what} must be strictly increasing")
        return [float(v) for v in values]


def validate(cfg: DictConfig) -> None:
    """Raise ConfigError for the first value of a composed config that cannot work."""
    check = _Checks(cfg)
    _known_keys(cfg)
    _run(check)
    _env(check)
    _coder(check)
    _policy(check)
    _distance(check)
    _curriculum(check)
    _perturbation(check)
    _walk(check)
    _movement(check)
    _motion(check)
    _stimuli(check)  # last: a folder of images is decoded here (once per process)


def _known_keys(cfg: DictConfig) -> None:
    """No setting the schema lacks (``+key=…`` can add one), none left at ``???``."""
    for key in sorted(schema_keys(cfg) - schema_keys()):
        value = OmegaConf.select(cfg, key, throw_on_missing=False)
        close = closest_key(key)
        raise ConfigError(
            key, value, "no such setting" + (f"; did you mean {close}?" if close else "")
        )
    for key in sorted(OmegaConf.missing_keys(cfg) - RUN_TIME_KEYS):
        raise ConfigError(key, "???", "must be given a value")


def _run(check: _Checks) -> None:
    check.integer("seed", 0)
    device = str(check.get("device"))
    kind, _, index = device.partition(":")
    if kind not in ("cpu", "cuda") or (kind == "cpu" and index) or (index and not index.isdigit()):
        check.fail("device", device, "must be cpu, cuda or cuda:<n>")
    if kind == "cuda":
        import torch

        if not torch.cuda.is_available():
            check.fail("device", device, "torch sees no CUDA device here; use device=cpu")
        if index and int(index) >= torch.cuda.device_count():
            check.fail("device", device, f"torch sees {torch.cuda.device_count()} CUDA device(s)")
    check.integer("train.presentations", 1)
    check.integer("train.checkpoint_every", 1, " (presentations)")
    check.integer("train.image_every", 1, " (presentations)")
    check.integer("train.threads", 0, " (0: torch's default)")
    if check.get("train.start_jitter_presentations") is not None:
        check.integer("train.start_jitter_presentations", 0, " or null")
    check.choice("train.distance_readout", READOUTS)
    check.choice("train.resume_from", RESUME_FROM)
    check.number("train.critic_scale_warning", above=0, what=" (|v·φ|)")
    if check.get("train.stop_after_non_finite") is not None:
        check.integer("train.stop_after_non_finite", 1, " (presentations) or null")
    check.integer("metrics.mae_window", 1, " (trials)")
    check.integer("metrics.summary_trials", 1, " (trials)")
    check.integer("metrics.distance_window", 1, " (predictions)")


def _env(check: _Checks) -> None:
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


def _coder(check: _Checks) -> None:
    scales = check.get("coder.scales")
    specs = check.get("coder.scale_specs") or {}
    if not scales:
        check.fail("coder.scales", scales, "needs at least one scale")
    if len(set(scales)) != len(scales):
        check.fail("coder.scales", scales, "must not name a scale twice")
    for name in scales:
        if name not in specs:
            check.fail("coder.scales", scales, f"{name!r} has no coder.scale_specs entry")
    image_size = int(check.get("env.image_size"))
    for name in scales:
        key = f"coder.scale_specs.{name}"
        window = check.integer(f"{key}.window", 1, " (pixels)")
        subsample = check.integer(f"{key}.subsample", 1)
        patch = check.integer(f"{key}.patch", 1, " (pixels)")
        check.integer(f"{key}.stride", 1, " (pixels)")
        if subsample & (subsample - 1):
            check.fail(f"{key}.subsample", subsample, "must be a power of 2 (Gaussian pyramid)")
        if window > image_size:
            check.fail(f"{key}.window", window, f"is larger than env.image_size={image_size}")
        side = window
        for _ in range(subsample.bit_length() - 1):
            side = (side + 1) // 2  # the pyramid's pyrDown maps n px to ⌈n/2⌉
        if side < patch:
            check.fail(
                f"{key}.window",
                window,
                f"sub-sampled ×{subsample} gives {side} px, fewer than the patch side {patch}",
            )
    check.integer("coder.atoms", 1, " (basis functions)")
    check.integer("coder.sparsity", 1, " (matching-pursuit steps)")
    check.number("coder.learning_rate", at_least=0)
    from parallax.coding.retina import NORMALISATIONS

    check.choice("coder.normalisation", NORMALISATIONS)
    check.choice("coder.robot_updates", ROBOT_UPDATES)


def _policy(check: _Checks) -> None:
    actions = check.get("policy.actions")
    if not isinstance(actions, list) or len(set(actions)) < 2:
        check.fail("policy.actions", actions, "needs at least two distinct pan increments")
    largest = float(check.get("env.max_pan_increment_deg"))
    for action in actions:
        if not math.isfinite(action):
            check.fail("policy.actions", actions, "must be finite pan increments in degrees")
        if abs(action) > largest + 1e-9:
            check.fail(
                "policy.actions",
                actions,
                f"{action:g}° is beyond env.max_pan_increment_deg={largest:g}",
            )
    for key in ("critic_lr", "advantage_lr", "actor_lr", "weight_decay", "reward_change_gain"):
        check.number(f"policy.{key}", at_least=0)
    check.number("policy.discount", at_least=0, at_most=1)
    check.number("policy.reward_rate", above=0, at_most=1)
    check.number("policy.temperature", above=0)
    actor_lr, decay = float(check.get("policy.actor_lr")), float(check.get("policy.weight_decay"))
    if actor_lr * decay >= 1:
        check.fail(
            "policy.weight_decay",
            decay,
            f"policy.actor_lr·policy.weight_decay must be below 1 (actor_lr={actor_lr:g})",
        )
    from parallax.policy.features import FEATURE_NORMS

    check.choice("policy.feature_norm", FEATURE_NORMS)
    check.choice("policy.robot_updates", ROBOT_UPDATES)
    check.integer("policy.zscore_horizon", 0, " (states; 0: all)")
    check.number("policy.eye_position_reference_m", at_least=0, what=" (metres; 0: off)")
    check.optional_number("policy.actor_projection_radius", above=0, what=" or null")
    check.number("policy.initial_actor_range", at_least=0)
    check.number("policy.initial_critic_range", at_least=0)


def _distance(check: _Checks) -> None:
    queue = check.integer("distance.queue_size", 1, " (the queue length c)")
    hidden = check.integer("distance.hidden", 1, " (hidden units)")
    check.number("distance.y", above=0, what=" (eq. 12's y)")
    check.integer("distance.sensitivity.patch", 1, " (pixels)")
    check.number("distance.sensitivity.subsample", at_least=1)
    check.number("distance.sensitivity.nearest_distance", above=0, what=" (metres)")
    check.number("distance.sensitivity.tolerance", at_least=0, what=" (pixels)")
    check.integer("distance.epochs_per_call", 1)
    check.integer("distance.initial_epochs", 1)
    lm = "distance.lm"
    check.number(f"{lm}.mu", above=0)
    check.number(f"{lm}.mu_decrease", above=0, below=1)
    check.number(f"{lm}.mu_increase", above=1)
    check.number(f"{lm}.mu_max", above=0)
    check.number(f"{lm}.min_grad", at_least=0)
    check.number(f"{lm}.weight_decay", at_least=0)
    max_params = check.integer(f"{lm}.max_params", 1)
    max_jacobian = check.integer(f"{lm}.max_jacobian_elements", 1)
    inputs = len(check.get("curriculum.lateral_positions") or [])
    params = (inputs + 1) * hidden + hidden + 1  # eqs. (13)–(15): weights and biases
    if params > max_params:
        check.fail(
            "distance.hidden",
            hidden,
            f"gives {params} network parameters, more than distance.lm.max_params={max_params}",
        )
    if queue * params > max_jacobian:
        check.fail(
            "distance.queue_size",
            queue,
            f"× {params} parameters exceeds distance.lm.max_jacobian_elements={max_jacobian}",
        )
    from parallax.distance.estimators import ESTIMATORS
    from parallax.distance.network import INPUT_SCALINGS
    from parallax.distance.targets import TARGET_SOURCES

    check.choice("distance.input_scaling", INPUT_SCALINGS)
    held_out = 0.0
    for key in ("validation_fraction", "test_fraction"):
        held_out += check.number(f"distance.{key}", at_least=0, below=1)
    if held_out >= 1:
        check.fail(
            "distance.test_fraction",
            check.get("distance.test_fraction"),
            "and distance.validation_fraction must leave some of the queue to fit",
        )
    check.integer("distance.max_fail", 1, " (epochs)")
    check.choice("distance.estimator", ESTIMATORS)
    check.choice("distance.targets", sorted(TARGET_SOURCES))
    check.number("distance.odometry.walk_fraction", above=0, at_most=1)
    check.number("distance.odometry.nominal_stride_m", above=0, what=" (metres)")
    if check.get("distance.fit_from") is not None:
        fit_from = check.integer("distance.fit_from", 1)
        if fit_from > queue:
            check.fail(
                "distance.fit_from", fit_from, f"must be ≤ distance.queue_size={queue}, or null"
            )


def _walk(check: _Checks) -> None:
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


def _movement(check: _Checks) -> None:
    route = check.choice("movement.route", ROUTES)
    check.number("movement.price_per_trial", at_least=0, what=" (percentage points per trial)")
    check.number("movement.price_per_cm", at_least=0, what=" (percentage points per cm)")
    check.number("movement.explore", above=0, at_most=1)
    if route == "planned":
        queue = check.get("distance.queue_size")
        if queue < 2:
            check.fail(
                "distance.queue_size",
                queue,
                "movement.route=planned needs at least 2 (its leave-one-out errors)",
            )
        if check.get("env.robots") != 1:
            check.fail("env.robots", check.get("env.robots"), "movement.route=planned needs 1")
        if check.get("distance.targets") != "supervisor":
            check.fail(
                "distance.targets",
                check.get("distance.targets"),
                "movement.route=planned learns from the supervisor's distances",
            )
        if check.get("curriculum.stages") is not None:
            check.fail(
                "curriculum.stages",
                check.get("curriculum.stages"),
                "movement.route=planned plans over all of L: leave the stages null",
            )


def _motion(check: _Checks) -> None:
    from parallax.envs.sweep import (
        MOTIONS,
        SWEEP_PROFILES,
        fastest_followable_speed_m,
        fastest_target_pan_deg,
    )

    check.choice("coder.pairing", PAIRINGS)
    motion = check.choice("env.motion", MOTIONS)
    speed = check.number("env.sweep.speed_m", above=0, what=" (metres per iteration)")
    profile = check.choice("env.sweep.profile", SWEEP_PROFILES)
    if motion != "continuous":
        return
    if check.get("movement.route") != "list":
        check.fail("movement.route", check.get("movement.route"), "env.motion=continuous sweeps L")
    if check.get("train.distance_readout") != "last":
        check.fail(
            "train.distance_readout",
            check.get("train.distance_readout"),
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


def _curriculum(check: _Checks) -> None:
    key = "curriculum.lateral_positions"
    lateral = check.positions(key, check.get(key), "the lateral list L")
    stages = check.get("curriculum.stages")
    if stages is not None:
        if not stages:
            check.fail("curriculum.stages", stages, "must hold at least one stage, or be null")
        for i, stage in enumerate(stages):
            stage_key = f"curriculum.stages[{i}]"
            check.positions(stage_key, stage, "a stage")
            if not set(stage) <= set(lateral):
                check.fail(stage_key, stage, f"must be a subset of {key}")
        if [float(v) for v in stages[-1]] != lateral:
            check.fail("curriculum.stages", stages, f"the last stage must equal {key}")
    check.number("curriculum.advance_below_deg", above=0, what=" (degrees)")
    check.integer("curriculum.min_trials", 1)


def _perturbation(check: _Checks) -> None:
    rotation = check.number("perturbation.camera_rotation_deg", what=" (degrees)")
    blur = check.number("perturbation.blur_sigma", at_least=0, what=" (pixels)")
    axis = check.get("perturbation.rotation_axis")
    from parallax.envs.hoap3 import ROTATION_AXES

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


def validate_stimuli(cfg: DictConfig) -> None:
    """Raise ConfigError for the first env.stimuli value that cannot work: the part of
    :func:`validate` that parallax-eval asks of the held-out textures it is given."""
    _stimuli(_Checks(cfg))


def _stimuli(check: _Checks) -> None:
    from parallax.envs.stimuli import (
        PROCEDURAL_KINDS,
        RESOLUTIONS,
        SOURCES,
        SPLITS,
        StimulusError,
        load_stimuli,
    )

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
    try:  # a folder of images is decoded here, once per process
        load_stimuli(check.get("env.stimuli"))
    except StimulusError as error:
        check.fail(f"env.stimuli.{error.key}", error.value, error.reason)
