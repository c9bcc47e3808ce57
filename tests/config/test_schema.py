"""One source of defaults: the schema (parallax/config/schema.py) against the components'
constructors and the conf/ files."""

from __future__ import annotations

import inspect
from pathlib import Path

import pytest
import yaml
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from parallax.coding import MultiScaleCoder
from parallax.config import (
    CoderConfig,
    Config,
    DistanceConfig,
    PolicyConfig,
    compose,
)
from parallax.config.schema import (
    GROUPS,
    SCHEMA_NODE,
    LevenbergMarquardtConfig,
    OdometryConfig,
    StimuliConfig,
)
from parallax.distance import DistanceLearner, LevenbergMarquardt, OdometryTargets
from parallax.distance.learner import DEFAULT_SENSITIVITY
from parallax.envs.stimuli import normalise_settings
from parallax.policy import NaturalActorCritic

CONF = Path(__file__).resolve().parents[2] / "conf"
#: Constructor arguments that are not settings of a run (implementation choices of the tests and
#: benchmarks).
NOT_SETTINGS = {MultiScaleCoder: {"pursuit"}}
#: Arguments whose default None stands for a nested node of the schema, and that node's defaults.
NESTED = {
    DistanceLearner: {"sensitivity": DEFAULT_SENSITIVITY, "lm": None, "odometry": OdometryTargets}
}


def _defaults(function) -> dict[str, object]:
    return {
        name: p.default
        for name, p in inspect.signature(function).parameters.items()
        if p.default is not inspect.Parameter.empty
    }


def _plain(value):
    return list(value) if isinstance(value, tuple) else value


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
    schema = OmegaConf.to_container(OmegaConf.structured(node))
    parameters = set(inspect.signature(component).parameters) - {"self"}
    # every setting reaches the constructor (instantiate passes them all) and nothing else does
    assert set(schema) - {"_target_"} == parameters - NOT_SETTINGS.get(component, set())
    for name, default in _defaults(component).items():
        if name in NOT_SETTINGS.get(component, set()):
            continue
        if name in NESTED.get(component, {}):
            assert default is None, name
            continue
        assert _plain(default) == schema[name], f"{component.__name__}({name}={default!r})"
    # settings known only at run time have no default to disagree with
    for name, value in schema.items():
        if value == "???":
            assert name not in _defaults(component), name


def test_the_nested_defaults_are_the_schemas():
    lm = OmegaConf.to_container(OmegaConf.structured(LevenbergMarquardtConfig))
    assert _defaults(LevenbergMarquardt) == lm
    sensitivity = OmegaConf.to_container(OmegaConf.structured(DistanceConfig)).get("sensitivity")
    assert DEFAULT_SENSITIVITY == sensitivity
    assert normalise_settings({}) == OmegaConf.to_container(OmegaConf.structured(StimuliConfig))
    odometry = OmegaConf.to_container(OmegaConf.structured(OdometryConfig))
    assert _defaults(OdometryTargets) == odometry


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
    from parallax.config.validate import RUN_TIME_KEYS

    # the values only the trainer knows, and nothing else, are left open
    assert OmegaConf.missing_keys(cfg) == RUN_TIME_KEYS


def test_the_world_factory_defaults_are_the_schemas():
    """parallax.envs.load's defaults are the schema's env (and perturbation) settings, so that
    ``load(seed=0)`` is the default task (dm_control's ``suite.load`` convention)."""
    import parallax.envs
    from parallax.config.schema import EnvConfig, PerturbationConfig

    defaults = _defaults(parallax.envs.load)
    env = OmegaConf.to_container(OmegaConf.structured(EnvConfig))
    perturbation = OmegaConf.to_container(OmegaConf.structured(PerturbationConfig))
    keys = ("trial_length", "image_size", "pan_reset", "max_pan_increment_deg")
    for key in (*keys, "initial_pan_jitter_deg"):
        assert _plain(defaults[key]) == env[key], key
    for key in ("camera_rotation_deg", "rotation_axis", "blur_sigma"):
        assert _plain(defaults[key]) == perturbation[key], key
    assert parallax.envs.distance_grid(defaults["distances"]) == parallax.envs.distance_grid(
        env["distances"]
    )
