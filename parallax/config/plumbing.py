"""Hydra plumbing for the apps: composing the configuration, naming run directories, reading a
run's saved configuration back and comparing it with another one.

The settings themselves are in :mod:`parallax.config.schema` (each part's in its
``settings.py``, beside their checks); :mod:`parallax.config.validate` runs the checks.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from parallax.config.schema import Config, SweepConfig, register
from parallax.envs.settings import growth_start

#: The Hydra config package; ``conf/`` ships inside the installed package as ``parallax.conf``.
CONFIG_MODULE = "parallax.conf"
CONFIG_NAME = "config"
#: File systems refuse names over 255 bytes; longer override lists keep a prefix and a hash.
MAX_RUN_NAME = 120


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


def config_groups() -> str:
    """The config groups of ``parallax-train --help`` and their options, one group a line: the
    files of conf/, without the schema's internal nodes (each group's ``schema``) and Hydra's
    own groups."""
    from importlib.resources import files

    lines = []
    for group in sorted(files(CONFIG_MODULE).iterdir(), key=lambda path: path.name):
        if not group.is_dir() or group.name in ("hydra", "__pycache__"):
            continue
        options = sorted(
            f.name.removesuffix(".yaml") for f in group.iterdir() if f.name.endswith(".yaml")
        )
        if options:
            lines.append(f"{group.name}: {', '.join(options)}")
    return "\n".join(lines)


def register_resolvers() -> None:
    if not OmegaConf.has_resolver("run_name"):
        OmegaConf.register_new_resolver("run_name", run_name)
    if not OmegaConf.has_resolver("config_groups"):
        OmegaConf.register_new_resolver("config_groups", config_groups)


def compose(overrides: Sequence[str] = (), with_hydra: bool = False) -> DictConfig:
    """The composed configuration for these overrides, as `parallax-train` would see it; with
    ``with_hydra``, Hydra's own node too (``hydra.run.dir`` & co.; see :func:`without_hydra`).

    Without Hydra's node, the same overrides are composed once per process (the config files do
    not change while parallax runs; Hydra takes about half a second a composition) and each
    caller gets its own copy."""
    if with_hydra:  # Hydra's node holds the working directory and the time: composed each time
        return _hydra_compose(tuple(overrides), with_hydra=True)
    return copy.deepcopy(_composed(tuple(overrides)))


@functools.lru_cache(maxsize=128)
def _composed(overrides: tuple[str, ...]) -> DictConfig:
    return _hydra_compose(overrides, with_hydra=False)


def _hydra_compose(overrides: tuple[str, ...], with_hydra: bool) -> DictConfig:
    from hydra import compose as hydra_compose
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    register()
    register_resolvers()
    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        return hydra_compose(
            config_name=CONFIG_NAME, overrides=list(overrides), return_hydra_config=with_hydra
        )


def without_hydra(cfg: DictConfig) -> DictConfig:
    """The run's configuration from one composed ``with_hydra``: Hydra's node left out, as Hydra
    hands it to the task."""
    from omegaconf import open_dict

    task = cfg.copy()
    with open_dict(task):
        task.pop("hydra", None)
    return task


RUN_CONFIG_NAME = "config.yaml"


def schema_keys(node: Any = None, prefix: str = "") -> set[str]:
    """Every setting's dotted key (``env.stimuli.count``, …), from the schema (or ``node``).

    The scale specs and the rotation axis hold values of the user's choosing (a scale's name, a
    vector), so they count as one setting each.
    """
    node = OmegaConf.structured(Config) if node is None else node
    keys: set[str] = set()
    for key in node.keys():
        dotted = f"{prefix}{key}"
        value = node._get_node(key)
        if OmegaConf.is_dict(value) and dotted not in OPAQUE_KEYS and not value._is_none():
            keys |= schema_keys(value, dotted + ".")
        else:
            keys.add(dotted)
    return keys


def closest_key(key: str) -> str | None:
    """The schema's setting nearest to a misspelt ``key`` (None if none is near)."""
    import difflib

    known = sorted(schema_keys())
    parent, _, leaf = key.rpartition(".")
    siblings = {k.rpartition(".")[2]: k for k in known if k.rpartition(".")[0] == parent}
    close = difflib.get_close_matches(leaf, sorted(siblings), n=1, cutoff=0.8)
    if close:  # a misspelt name among its neighbours
        return siblings[close[0]]
    close = difflib.get_close_matches(key, known, n=1, cutoff=0.85)
    return close[0] if close else None


#: Settings whose value is a mapping or list of the user's choosing, compared as a whole.
OPAQUE_KEYS = frozenset({"coder.scale_specs", "perturbation.rotation_axis"})
#: Choices an older parallax wrote under other names: (group, setting) → {old name: name}.
#: "sum" (the coder's) and "in_turn" (the policy's) are both "each" (schema.ROBOT_UPDATES).
RENAMED_CHOICES = {
    ("coder", "robot_updates"): {"sum": "each"},
    ("policy", "robot_updates"): {"in_turn": "each"},
}
#: Settings an older parallax did not have, and the value that is what it did.
ADDED_SETTINGS = {
    ("policy", "learn_reset_step"): False,
    ("coder", "pairing"): "reference",
    ("env", "motion"): "pick_and_place",
    ("env", "sweep"): dataclasses.asdict(SweepConfig()),  # unread by pick-and-place
    ("distance", "warm_start"): True,
    ("distance", "keep_first_scaling"): False,
    ("env", "fovea_px"): None,  # every pixel rendered at full resolution
    ("distance", "estimator"): "network",
}


def upgrade_saved(config: Any) -> Any:
    """A saved configuration (a run's config.yaml, a checkpoint's "config"; a DictConfig or a
    plain dict) as a copy in this parallax's words: the choices an older parallax wrote under
    another name (RENAMED_CHOICES) renamed and the settings it did not have (ADDED_SETTINGS) at
    the value that is what it did, so that reading a run back, resuming it and comparing it with
    a freshly composed config see the same settings. Apply it wherever one is read."""
    upgraded = copy.deepcopy(config)

    def group_of(name: str) -> Any:  # the group's node, or None where the config has none
        node = upgraded.get(name) if isinstance(upgraded, (dict, DictConfig)) else None
        return node if isinstance(node, (dict, DictConfig)) else None

    for (group, key), names in RENAMED_CHOICES.items():
        node = group_of(group)
        if node is not None and node.get(key) in names:
            node[key] = names[node[key]]
    for (group, key), value in ADDED_SETTINGS.items():
        node = group_of(group)
        if node is not None and key not in node:
            node[key] = value
    return upgraded


def load_run_config(run_dir: str | Path) -> DictConfig:
    """The configuration a run was trained with (``<run>/config.yaml``, written by the trainer),
    typed by the schema.

    The file must hold every setting of the schema and nothing else: a setting it lacks is not
    given a value here (that would be a guess about how the run was trained), and one the schema
    no longer has cannot be honoured. Either is a ValueError naming the keys. Settings that
    never change results (RESULT_NEUTRAL_KEYS) are the exception: one the file lacks takes the
    schema's default, which changes nothing the run computed.
    """
    path = Path(run_dir) / RUN_CONFIG_NAME
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} is not a parallax run directory (no {RUN_CONFIG_NAME})")
    register_resolvers()
    saved = upgrade_saved(OmegaConf.load(path))
    have, want = schema_keys(saved), schema_keys()
    missing, unknown = sorted(want - have - RESULT_NEUTRAL_KEYS), sorted(have - want)
    if missing or unknown:
        parts = [f"lacks {', '.join(missing)}"] if missing else []
        parts += [f"has settings parallax does not know: {', '.join(unknown)}"] if unknown else []
        raise ValueError(
            f"{path} {'; '.join(parts)} (a run's config.yaml holds every setting of "
            "parallax/config/schema.py with the value the run was trained with)"
        )
    return OmegaConf.merge(OmegaConf.structured(Config), saved)


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
#: Settings that never change a run's results (the same list as the run-directory name ignores
#: in conf/config.yaml).
RESULT_NEUTRAL_KEYS = frozenset(
    {
        "device",
        "resume",
        "train.threads",
        "train.checkpoint_every",
        "train.image_every",
        "train.resume_from",
        "train.critic_scale_warning",
        "train.stop_after_non_finite",
    }
)
#: Settings that may differ when a run is resumed: those, and train.presentations (which only
#: changes how long the run goes on). perturbation.start_fraction and
#: env.walk.growth_start_fraction may differ too, so long as the presentation they start at
#: (with train.presentations: :func:`perturbation_start`, :func:`growth_start`) does not: a
#: finished run's continuation is lengthened with both.
RESUMABLE_CHANGES = RESULT_NEUTRAL_KEYS | {
    "train.presentations",
    "perturbation.start_fraction",
    "env.walk.growth_start_fraction",
}


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


def run_settings(config: dict) -> dict[str, Any]:
    """A run's settings as ``flatten`` gives them (its saved config holds every setting)."""
    return flatten(config)


def result_settings(flat: dict[str, Any], *, seed: bool = False) -> dict[str, Any]:
    """Flattened settings less those that change no result and those the trainer fills from the
    rest at run time, and less the seed unless ``seed``: what two runs of one launch share (with
    ``seed``, what makes two runs the same run)."""
    dropped = RESULT_NEUTRAL_KEYS | RUN_TIME_KEYS | (set() if seed else {"seed"})
    return {key: value for key, value in flat.items() if key not in dropped}


def changed_settings(
    saved: DictConfig, current: DictConfig, reached: int | None = None, schedule: bool = True
) -> list[str]:
    """``key: saved → current`` for every setting that differs between a run's saved config and
    the config it is being resumed with (RESUMABLE_CHANGES aside). A default that differs from
    the one the run was trained with shows up here, so a resumed run never mixes two settings
    silently. ``reached``: the presentations the checkpoint holds; a schedule point (the
    perturbation's start, the growth spurt) may then move where the run has reached neither its
    old nor its new presentation, since the run so far is the same under both (a phase before
    the perturbation lengthened). Without it, a schedule point may not move."""
    saved_dict = OmegaConf.to_container(saved, resolve=True)
    current_dict = OmegaConf.to_container(current, resolve=True)
    before, after = run_settings(saved_dict), run_settings(current_dict)
    changes = [
        f"{key}: {before.get(key, '(unset)')!r} → {after.get(key, '(unset)')!r}"
        for key in sorted(set(before) | set(after))
        if key not in RESUMABLE_CHANGES and before.get(key) != after.get(key)
    ]
    # train.presentations alone would move a fractional schedule point: compare where each is
    schedule_points = (
        (perturbation_start, "the perturbation's start presentation (perturbation.start_fraction"),
        (growth_start, "the growth spurt's presentation (env.walk.growth_start_fraction"),
    )
    for point, what in schedule_points if schedule else ():
        old, new = point(saved_dict), point(current_dict)
        if old != new and not _not_reached(reached, old, new):
            changes.append(f"{what} × train.presentations): {old} → {new}")
    return changes


def _not_reached(reached: int | None, *points: int | None) -> bool:
    """Whether a run that has completed ``reached`` presentations has seen none of the schedule
    ``points`` (None: never): the switch happens as presentation ``point`` begins, so a run that
    stopped at it has not seen it."""
    return reached is not None and all(p is None or reached <= p for p in points)


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


def start_jitter_on(cfg, presentation: int) -> bool:
    """Whether presentation ``presentation`` (0-based) starts its trials from the jittered pan of
    ``env.initial_pan_jitter_deg``: always when ``train.start_jitter_presentations`` is null,
    else only before that many presentations (the trainer and parallax-eval both use this)."""
    limit = cfg["train"]["start_jitter_presentations"]
    return limit is None or int(presentation) < int(limit)
