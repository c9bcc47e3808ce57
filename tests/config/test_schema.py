"""One source of defaults: the schema (parallax/config/schema.py) against the components'
constructors and the conf/ files."""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from pathlib import Path

import pytest
import torch
import yaml
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from parallax.coding import MultiScaleCoder, ScaleCoder
from parallax.config import (
    CoderConfig,
    Config,
    DistanceConfig,
    EnvConfig,
    PerturbationConfig,
    PolicyConfig,
    compose,
)
from parallax.config.schema import (
    GROUPS,
    SCHEMA_NODE,
    DistanceGridConfig,
    LevenbergMarquardtConfig,
    MovementConfig,
    OdometryConfig,
    SensitivityConfig,
    StimuliConfig,
    WalkConfig,
    default,
)
from parallax.distance import DistanceLearner, LevenbergMarquardt, OdometryTargets
from parallax.distance.network import DistanceMLP
from parallax.distance.planner import MovementPlanner
from parallax.distance.weighting import sensitive_positions
from parallax.envs import LateralPursuitTask, Physics
from parallax.envs.stimuli import normalise_settings
from parallax.envs.walk import Walker
from parallax.policy import NaturalActorCritic

CONF = Path(__file__).resolve().parents[2] / "conf"
#: Constructor arguments that are not settings of a run (implementation choices of the tests and
#: benchmarks).
NOT_SETTINGS = {MultiScaleCoder: {"pursuit"}}


def _defaults(function) -> dict[str, object]:
    return {
        name: _plain(p.default)
        for name, p in inspect.signature(function).parameters.items()
        if p.default is not inspect.Parameter.empty
    }


def _plain(value):
    """A keyword default as the schema's plain containers (read-only ones become dicts and
    lists)."""
    if isinstance(value, Mapping):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, tuple):
        return [_plain(item) for item in value]
    return value


def _schema(node) -> dict:
    return OmegaConf.to_container(OmegaConf.structured(node))


@pytest.mark.parametrize(
    "component, node",
    [
        (MultiScaleCoder, CoderConfig),
        (NaturalActorCritic, PolicyConfig),
        (DistanceLearner, DistanceConfig),
    ],
    ids=lambda v: getattr(v, "__name__", ""),
)
def test_constructor_defaults_are_the_schemas(component, node):
    schema = _schema(node)
    parameters = set(inspect.signature(component).parameters) - {"self"}
    # every setting reaches the constructor (instantiate passes them all) and nothing else does
    assert set(schema) - {"_target_"} == parameters - NOT_SETTINGS.get(component, set())
    for name, value in _defaults(component).items():
        if name not in NOT_SETTINGS.get(component, set()):
            assert value == schema[name], f"{component.__name__}({name}={value!r})"
    # settings known only at run time have no default to disagree with
    for name, value in schema.items():
        if value == "???":
            assert name not in _defaults(component), name


#: Every keyword default of the parts below: (function, {argument: the schema's value, or the
#: default of an argument that is no setting}).
PART_DEFAULTS = [
    (LevenbergMarquardt, _schema(LevenbergMarquardtConfig)),
    (OdometryTargets, _schema(OdometryConfig)),
    (Walker, _schema(WalkConfig)),
    (sensitive_positions, _schema(SensitivityConfig) | {"focal_px": 531.0}),
    (ScaleCoder, {"pursuit": "gram", "robot_updates": CoderConfig.robot_updates}),
    (
        DistanceMLP,
        {
            "hidden": DistanceConfig.hidden,
            "input_scaling": DistanceConfig.input_scaling,
            "generator": None,
            "dtype": torch.float64,
        },
    ),
    (
        MovementPlanner,
        {
            "queue_size": DistanceConfig.queue_size,
            "price_per_trial": MovementConfig.price_per_trial,
            "price_per_cm": MovementConfig.price_per_cm,
            "ridge": 1.0e-6,
        },
    ),
    (
        LateralPursuitTask,
        {
            "pan_reset": EnvConfig.pan_reset,
            "max_pan_increment_deg": EnvConfig.max_pan_increment_deg,
            "initial_pan_jitter_deg": EnvConfig.initial_pan_jitter_deg,
            "random": None,
            "motion": EnvConfig.motion,
            "sweep": default(EnvConfig, "sweep"),
        },
    ),
    (
        Physics.create,
        {
            "image_size": EnvConfig.image_size,
            "max_distance_m": DistanceGridConfig.stop,
            "fovea_px": EnvConfig.fovea_px,
        },
    ),
]


@pytest.mark.parametrize(
    "function, expected", PART_DEFAULTS, ids=lambda v: getattr(v, "__qualname__", "")
)
def test_the_parts_defaults_are_the_schemas(function, expected):
    defaults = _defaults(function)
    # a walker takes its growth spurt as a presentation (growth_start), env.walk.
    # growth_start_fraction of the run: the only key it lacks, and the only one it adds
    if function is Walker:
        defaults.pop("growth_start")
    assert {k: v for k, v in expected.items() if k in defaults} == defaults
    assert set(expected) - set(defaults) <= {"growth_start_fraction"}


def test_the_stimulus_defaults_are_the_schemas():
    assert normalise_settings({}) == _schema(StimuliConfig)


def test_a_default_is_a_read_only_copy_of_the_schemas():
    specs = default(CoderConfig, "scale_specs")
    assert _plain(specs) == _schema(CoderConfig)["scale_specs"]
    assert default(CoderConfig, "scales") == ("coarse", "fine")
    assert default(CoderConfig, "atoms") == CoderConfig.atoms
    with pytest.raises(TypeError):
        specs["coarse"]["window"] = 1  # type: ignore[index]


def test_plain_parallax_train_is_the_schema():
    """The default choices of conf/config.yaml add nothing to the schema's defaults."""
    assert OmegaConf.to_container(compose([])) == OmegaConf.to_container(
        OmegaConf.structured(Config)
    )


@pytest.mark.parametrize(
    "path",
    sorted(p for group in GROUPS for p in (CONF / group).glob("*.yaml")),
    ids=lambda p: f"{p.parent.name}/{p.stem}",
)
def test_group_files_extend_the_schema_and_restate_no_default(path):
    text = yaml.safe_load(path.read_text()) or {}
    assert text.pop("defaults") == [SCHEMA_NODE, "_self_"]
    schema = OmegaConf.to_container(OmegaConf.structured(GROUPS[path.parent.name]))
    for key, value in text.items():
        assert schema[key] != value, f"{path.name} restates the default {key}={value!r}"


@pytest.mark.parametrize(
    "override, message",
    [
        ("train.presentations=abc", "could not be converted to Integer"),
        ("env.pan_reset=maybe", "pan_reset"),
        ("policy.actions=[left]", "could not be converted to Float"),
        ("train.start_jitter_presentations=0.5", "could not be converted to Integer"),
        ("foo.bar=1", "Could not override 'foo.bar'"),
    ],
)
def test_hydra_checks_types_and_keys_against_the_schema(override, message):
    with pytest.raises(ConfigCompositionException) as error:
        compose([override])
    assert message in f"{error.value} {error.value.__cause__}"


def test_run_time_values_stay_missing():
    cfg = compose([])
    from parallax.config import RUN_TIME_KEYS

    # the values only the trainer knows, and nothing else, are left open
    assert OmegaConf.missing_keys(cfg) == RUN_TIME_KEYS


def test_the_world_factory_defaults_are_the_schemas():
    """parallax.envs.load's defaults are the schema's env (and perturbation) settings, so that
    ``load(seed=0)`` is the default task (dm_control's ``suite.load`` convention)."""
    import parallax.envs

    defaults = _defaults(parallax.envs.load)
    env, perturbation = _schema(EnvConfig), _schema(PerturbationConfig)
    keys = ("trial_length", "image_size", "pan_reset", "max_pan_increment_deg")
    for key in (*keys, "initial_pan_jitter_deg", "distances", "stimuli"):
        assert defaults[key] == env[key], key
    for key in ("camera_rotation_deg", "rotation_axis", "blur_sigma"):
        assert defaults[key] == perturbation[key], key
