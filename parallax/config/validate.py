"""Ranges and cross-field rules of the configuration, checked before anything is built or written.

Hydra checks each value's type against :mod:`parallax.config.schema`; :func:`validate` checks
what a type cannot say: that a number is finite and in range, a choice is one the components
know, lists are non-empty and ordered, and settings that depend on each other agree (a window
fits in the image, every action is a pan increment the world accepts, …). Each part's checks
sit beside its settings (its ``settings.py``); the run's own (the schedule, the metrics, the
lateral list) are here, and :func:`validate` runs them all. Each failure is a
:class:`ConfigError` naming the first key and value that cannot work, so `parallax-train` can
stop with one line before Hydra creates a run directory, and a sweep's job before the trainer
writes into its directory. A component built from a config trusts its settings, and raises
only for what a config cannot say (the shapes of the tensors it is handed, the arguments of a
call at run time, the content of a file).
"""

from __future__ import annotations

from omegaconf import DictConfig, OmegaConf

from parallax import readouts
from parallax.checks import Checks, ConfigError
from parallax.coding import settings as coder
from parallax.config.plumbing import RUN_TIME_KEYS, closest_key, schema_keys
from parallax.distance import settings as distance
from parallax.envs import settings as world
from parallax.envs import stimuli
from parallax.policy import settings as policy

#: train.resume_from: the latest checkpoint, or the one written before it.
RESUME_FROM = ("latest", "previous")


def validate(cfg: DictConfig) -> None:
    """Raise ConfigError for the first value of a composed config that cannot work."""
    check = Checks(cfg)
    _known_keys(cfg)
    _run(check)
    world.check_env(check)
    coder.check(check)
    policy.check(check)
    distance.check(check)
    _curriculum(check)
    world.check_perturbation(check)
    world.check_walk(check)
    distance.check_movement(check)
    world.check_motion(check)
    world.check_stimuli(check)
    stimuli.check_loadable(check)  # last: a folder of images is decoded here (once per process)


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


def _run(check: Checks) -> None:
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
    check.choice("train.distance_readout", readouts.READOUTS)
    check.choice("train.resume_from", RESUME_FROM)
    check.number("train.critic_scale_warning", above=0, what=" (|v·φ|)")
    if check.get("train.stop_after_non_finite") is not None:
        check.integer("train.stop_after_non_finite", 1, " (presentations) or null")
    check.integer("metrics.mae_window", 1, " (trials)")
    check.integer("metrics.summary_trials", 1, " (trials)")
    check.integer("metrics.distance_window", 1, " (predictions)")


def _curriculum(check: Checks) -> None:
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


def validate_stimuli(cfg: DictConfig) -> None:
    """Raise ConfigError for the first env.stimuli value that cannot work: the part of
    :func:`validate` that parallax-eval asks of the held-out textures it is given."""
    check = Checks(cfg)
    world.check_stimuli(check)
    stimuli.check_loadable(check)
