"""The configuration of `parallax-train` and the tools: the schema, its checks, the Hydra plumbing.

``schema``    every setting as a typed dataclass field with its one default (registered in
              Hydra's ConfigStore on import; conf/ files extend it)
``validate``  every part's ranges and cross-field rules, checked before anything is written
``plumbing``  composing, run-directory names, reading a run's saved config back (in this
              parallax's words: ``upgrade_saved``), comparing two
Each part's settings and checks are in its ``settings.py`` (parallax.envs, parallax.coding,
parallax.policy, parallax.distance), the one-line ``key=value: reason`` ConfigError in
parallax.checks, below them all; this package gathers them and imports nothing above them.
"""

from parallax.checks import ConfigError, format_value
from parallax.config.plumbing import (
    CONFIG_MODULE,
    CONFIG_NAME,
    MAX_RUN_NAME,
    OPAQUE_KEYS,
    RESULT_NEUTRAL_KEYS,
    RESUMABLE_CHANGES,
    RUN_CONFIG_NAME,
    RUN_TIME_KEYS,
    changed_settings,
    compose,
    flatten,
    freeze_value,
    growth_start,
    load_run_config,
    perturbation_start,
    register_resolvers,
    result_settings,
    run_name,
    run_settings,
    schema_keys,
    start_jitter_on,
    upgrade_saved,
)
from parallax.config.schema import (
    ROBOT_UPDATES,
    CoderConfig,
    Config,
    CurriculumConfig,
    DistanceConfig,
    EnvConfig,
    MetricsConfig,
    PerturbationConfig,
    PolicyConfig,
    TrainConfig,
    default,
    register,
)
from parallax.config.validate import validate, validate_stimuli

register()

__all__ = [
    "CONFIG_MODULE",
    "CONFIG_NAME",
    "MAX_RUN_NAME",
    "OPAQUE_KEYS",
    "RESULT_NEUTRAL_KEYS",
    "RESUMABLE_CHANGES",
    "ROBOT_UPDATES",
    "RUN_CONFIG_NAME",
    "RUN_TIME_KEYS",
    "CoderConfig",
    "Config",
    "ConfigError",
    "CurriculumConfig",
    "DistanceConfig",
    "EnvConfig",
    "MetricsConfig",
    "PerturbationConfig",
    "PolicyConfig",
    "TrainConfig",
    "changed_settings",
    "compose",
    "default",
    "growth_start",
    "flatten",
    "format_value",
    "freeze_value",
    "load_run_config",
    "perturbation_start",
    "register",
    "register_resolvers",
    "result_settings",
    "run_name",
    "run_settings",
    "schema_keys",
    "start_jitter_on",
    "upgrade_saved",
    "validate",
    "validate_stimuli",
]
