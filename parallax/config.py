"""Configuration plumbing for the Hydra apps: composing, naming run directories, validating.

Hydra creates the run directory before the task function runs, so `parallax-train` composes
and validates the configuration first (``compose`` + ``validate``) and only then hands over to
Hydra: a bad config fails with one line naming the key and nothing is written.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

#: The Hydra config package; ``conf/`` ships inside the installed package as ``parallax.conf``.
CONFIG_MODULE = "parallax.conf"
CONFIG_NAME = "config"
#: File systems refuse names over 255 bytes; longer override lists keep a prefix and a hash.
MAX_RUN_NAME = 120


class ConfigError(ValueError):
    """A configuration value that cannot work; the message names the key."""

    def __init__(self, key: str, reason: str):
        super().__init__(f"{key}: {reason}")
        self.key, self.reason = key, reason

    def __reduce__(self):
        # Launchers (joblib, submitit) send a failed job's exception back by pickling it.
        return (type(self), (self.key, self.reason))


def run_name(override_dirname: str) -> str:
    """Run-directory name from the command-line overrides ('default' when there are none)."""
    if not override_dirname:
        return "default"
    # '/' would nest directories and '[]' upsets shells; keep names readable and flat.
    name = re.sub(r"[^A-Za-z0-9_.,=+-]", "", override_dirname.replace("/", "-")) or "default"
    if len(name) > MAX_RUN_NAME:
        digest = hashlib.sha1(override_dirname.encode()).hexdigest()[:10]
        name = f"{name[: MAX_RUN_NAME - 11]}-{digest}"
    return name


def register_resolvers() -> None:
    if not OmegaConf.has_resolver("run_name"):
        OmegaConf.register_new_resolver("run_name", run_name)


def compose(overrides: Sequence[str] = ()) -> DictConfig:
    """The composed configuration for these overrides, as `parallax-train` would see it."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    register_resolvers()
    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        return hydra_compose(config_name=CONFIG_NAME, overrides=list(overrides))


RUN_CONFIG_NAME = "config.yaml"


def load_run_config(run_dir: str | Path) -> DictConfig:
    """The configuration a run was composed with (``<run>/config.yaml``, written by the trainer)."""
    path = Path(run_dir) / RUN_CONFIG_NAME
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} is not a parallax run directory (no {RUN_CONFIG_NAME})")
    register_resolvers()
    return OmegaConf.load(path)


#: Settings that never change a run's results (the same list as the run-directory name ignores
#: in conf/config.yaml).
RESULT_NEUTRAL_KEYS = frozenset(
    {"device", "resume", "train.threads", "train.checkpoint_every", "train.image_every"}
)
#: Settings that may differ when a run is resumed: those, and train.presentations (which only
#: changes how long the run goes on). perturbation.start_fraction may differ too, so long as the
#: presentation it starts at (with train.presentations, :func:`perturbation_start`) does not: a
#: finished run's continuation after the perturbation is lengthened with both.
RESUMABLE_CHANGES = RESULT_NEUTRAL_KEYS | {"train.presentations", "perturbation.start_fraction"}


def freeze_value(value: Any) -> Any:
    """A hashable copy of a config value (lists become tuples), as run settings hold it."""
    if isinstance(value, dict):
        return tuple(sorted((k, freeze_value(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(freeze_value(v) for v in value)
    return value


def flatten(config: dict, prefix: str = "") -> dict[str, Any]:
    """{'coder.scales': ('coarse', 'fine'), …}: dotted keys, hashable values."""
    flat: dict[str, Any] = {}
    for key, value in config.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            flat.update(flatten(value, dotted + "."))
        else:
            flat[dotted] = freeze_value(value)
    return flat


#: Settings added to conf/ after runs had been made without them, with the value such runs were
#: trained with: a saved config that lacks one of them is read as having that value, so adding a
#: setting neither blocks resuming old runs nor makes it look like an ablation in a report.
SETTINGS_ADDED_LATER: dict[str, Any] = {
    "distance.outlier_mads": None,
    "distance.lm.weight_decay": 0.0,
    "env.initial_pan_jitter_deg_per_m": 0.0,
    "policy.eye_position_reference_m": 0.0,
    "policy.reward_change_gain": 0.0,
    "train.start_jitter_presentations": None,
    "train.distance_readout": "last",
}


def run_settings(config: dict) -> dict[str, Any]:
    """``flatten(config)`` with SETTINGS_ADDED_LATER filled in where the config predates them."""
    return {**SETTINGS_ADDED_LATER, **flatten(config)}


def changed_settings(saved: DictConfig, current: DictConfig) -> list[str]:
    """``key: saved → current`` for every setting that differs between a run's saved config and
    the config it is being resumed with (RESUMABLE_CHANGES aside). A default changed in conf/
    since the run started shows up here, so a resumed run never mixes two settings silently."""
    saved_dict = OmegaConf.to_container(saved, resolve=True)
    current_dict = OmegaConf.to_container(current, resolve=True)
    before, after = run_settings(saved_dict), run_settings(current_dict)
    changes = [
        f"{key}: {before.get(key, '(unset)')!r} → {after.get(key, '(unset)')!r}"
        for key in sorted(set(before) | set(after))
        if key not in RESUMABLE_CHANGES and before.get(key) != after.get(key)
    ]
    # train.presentations alone would move a fractional perturbation start: compare where it starts
    start_before, start_after = perturbation_start(saved_dict), perturbation_start(current_dict)
    if start_before != start_after:
        changes.append(
            "the perturbation's start presentation (perturbation.start_fraction × "
            f"train.presentations): {start_before} → {start_after}"
        )
    return changes


def perturbation_start(cfg) -> int | None:
    """Presentation index at which §5's perturbation is switched on (None: never).

    The one place ``perturbation.start_fraction`` becomes a presentation; the trainer, the
    evaluation and the report all use it. ``cfg`` may be a DictConfig or a plain dict.
    """
    fraction = (cfg.get("perturbation") or {}).get("start_fraction")
    total = (cfg.get("train") or {}).get("presentations")
    if fraction is None or total is None:
        return None
    return int(round(float(fraction) * int(total)))


#: How a trial's pan becomes a component of s: "last", the pan at its last iteration (the paper's
#: q_p, eq. 16); "best_reward" (beyond the paper), the pan whose image the coder encoded best
#: during the trial. The trainer, parallax-replay and parallax-eval share these names.
#: Each readout names the Presentation field and the metrics.jsonl key that hold its pans.
READOUT_PANS = {"last": "pans", "best_reward": "best_pans"}
DISTANCE_READOUTS = tuple(READOUT_PANS)


def distance_readout(cfg) -> str:
    """The run's ``train.distance_readout`` ("last" for runs saved before it existed)."""
    return str((cfg.get("train") or {}).get("distance_readout") or "last")


def start_jitter_on(cfg, presentation: int) -> bool:
    """Whether presentation ``presentation`` (0-based) starts its trials from the jittered pan of
    ``env.initial_pan_jitter_deg…``: always when ``train.start_jitter_presentations`` is null,
    else only before that many presentations (the trainer and parallax-eval both use this)."""
    limit = (cfg.get("train") or {}).get("start_jitter_presentations")
    return limit is None or int(presentation) < int(limit)


def _require(cond: bool, key: str, reason: str) -> None:
    if not cond:
        raise ConfigError(key, reason)


def validate(cfg: DictConfig) -> None:
    """Raise ConfigError for the first value that cannot work."""
    lateral = list(cfg.curriculum.lateral_positions)
    _require(len(lateral) > 0, "curriculum.lateral_positions", "the lateral list L is empty")
    _require(
        all(isinstance(v, (int, float)) for v in lateral),
        "curriculum.lateral_positions",
        f"must be numbers in metres, got {lateral}",
    )
    _require(
        all(b > a for a, b in zip(lateral, lateral[1:])),
        "curriculum.lateral_positions",
        f"must be strictly increasing, got {lateral}",
    )
    if cfg.curriculum.get("stages"):
        for i, stage in enumerate(cfg.curriculum.stages):
            _require(
                len(stage) > 0 and set(stage) <= set(lateral),
                f"curriculum.stages[{i}]",
                f"must be a non-empty subset of curriculum.lateral_positions, got {list(stage)}",
            )
        _require(
            list(cfg.curriculum.stages[-1]) == lateral,
            "curriculum.stages",
            "the last stage must equal curriculum.lateral_positions",
        )
    _require(
        int(cfg.env.trial_length) >= 2,
        "env.trial_length",
        f"needs at least 2 iterations per trial, got {cfg.env.trial_length}",
    )
    _require(
        int(cfg.env.get("robots", 1)) >= 1,
        "env.robots",
        f"must be ≥ 1, got {cfg.env.get('robots')}",
    )
    _require(
        int(cfg.distance.queue_size) >= 1,
        "distance.queue_size",
        f"the queue size c must be ≥ 1, got {cfg.distance.queue_size}",
    )
    scales = list(cfg.coder.scales)
    _require(len(scales) > 0, "coder.scales", "needs at least one scale")
    for s in scales:
        _require(
            s in cfg.coder.scale_specs,
            "coder.scales",
            f"unknown scale {s!r}; known: {sorted(cfg.coder.scale_specs)}",
        )
        window = int(cfg.coder.scale_specs[s].window)
        _require(
            window <= int(cfg.env.image_size),
            f"coder.scale_specs.{s}.window",
            f"window {window} px is larger than the image (env.image_size={cfg.env.image_size})",
        )
    _require(
        int(cfg.train.presentations) >= 1,
        "train.presentations",
        f"must be ≥ 1, got {cfg.train.presentations}",
    )
    _require(
        int(cfg.train.checkpoint_every) >= 1,
        "train.checkpoint_every",
        f"must be ≥ 1, got {cfg.train.checkpoint_every}",
    )
    _require(
        int(cfg.metrics.mae_window) >= 1,
        "metrics.mae_window",
        f"must be ≥ 1, got {cfg.metrics.mae_window}",
    )
    _require(
        cfg.device in ("cpu", "cuda") or str(cfg.device).startswith("cuda:"),
        "device",
        f"must be cpu or cuda, got {cfg.device!r}",
    )
    jitter_limit = cfg.train.get("start_jitter_presentations")
    _require(
        jitter_limit is None
        or (
            isinstance(jitter_limit, int)
            and not isinstance(jitter_limit, bool)
            and jitter_limit >= 0
        ),
        "train.start_jitter_presentations",
        f"must be null or a whole number of presentations ≥ 0, got {jitter_limit!r}",
    )
    readout = cfg.train.get("distance_readout", "last")
    _require(
        readout in DISTANCE_READOUTS,
        "train.distance_readout",
        f"must be one of {', '.join(DISTANCE_READOUTS)}, got {readout!r}",
    )
    start = cfg.perturbation.get("start_fraction")
    if start is not None:
        _require(
            0.0 <= float(start) <= 1.0,
            "perturbation.start_fraction",
            f"must be between 0 and 1, got {start}",
        )
