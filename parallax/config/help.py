"""`parallax-train --help`: what a plain run means, the experiments and their length, the config
groups, and every setting with this command line's value, its description and unit from the
schema's ``#:`` comments (parallax/config/schema.py)."""

from __future__ import annotations

import dataclasses
import inspect
import re
import textwrap
import typing
from collections.abc import Sequence
from functools import cache
from importlib.resources import files
from typing import Any

import yaml
from omegaconf import DictConfig, OmegaConf

from parallax.config import schema
from parallax.config.plumbing import CONFIG_MODULE, config_groups

_FIELD = re.compile(r"^\s+(\w+)\s*:")


def _comments(cls: type) -> dict[str, str]:
    """The ``#:`` comment above each field of the dataclass ``cls``, joined into one line."""
    found, pending = {}, []
    for line in inspect.getsource(cls).splitlines():
        stripped = line.strip()
        if stripped.startswith("#:"):
            pending.append(stripped[2:].strip())
        elif (match := _FIELD.match(line)) and not stripped.startswith(("#", '"')):
            if pending:
                found[match.group(1)] = " ".join(pending)
            pending = []
        elif stripped and not stripped.startswith("#"):
            pending = []
    return found


@cache
def descriptions() -> dict[str, str]:
    """Dotted setting (``*`` for a mapping's keys, as coder.scale_specs.*.window) → its
    description; a group's key → its dataclass's first docstring line."""
    found: dict[str, str] = {}

    def walk(cls: type, prefix: str) -> None:
        hints = typing.get_type_hints(cls)
        comments = _comments(cls)
        for f in dataclasses.fields(cls):
            key = f"{prefix}{f.name}"
            kind = hints[f.name]
            if dataclasses.is_dataclass(kind):
                found[key] = comments.get(f.name) or (inspect.getdoc(kind) or "").split("\n\n")[0]
                walk(kind, key + ".")
                continue
            if typing.get_origin(kind) is dict:
                inner = typing.get_args(kind)[1]
                if dataclasses.is_dataclass(inner):
                    walk(inner, key + ".*.")
            if f.name in comments:
                found[key] = comments[f.name]

    walk(schema.Config, "")
    return found


def _describe(key: str) -> str | None:
    table = descriptions()
    if key in table:
        return table[key]
    parts = key.split(".")
    for i in range(len(parts)):  # a mapping's own keys: coder.scale_specs.coarse.window
        wild = ".".join(parts[:i] + ["*"] + parts[i + 1 :])
        if wild in table:
            return table[wild]
    return None


def _value(value: Any) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, allow_unicode=True, width=10**6)
    return text.strip().removesuffix("...").strip()


def annotated(cfg: DictConfig) -> str:
    """``cfg`` as YAML, each setting under its description."""
    lines: list[str] = []

    def walk(node: dict, prefix: str, depth: int) -> None:
        indent = "  " * depth
        for key, value in node.items():
            dotted = f"{prefix}{key}"
            about = _describe(dotted)
            if about:
                width = max(40, 100 - len(indent) - 2)
                lines.extend(f"{indent}# {part}" for part in textwrap.wrap(about, width))
            if isinstance(value, dict) and value:
                lines.append(f"{indent}{key}:")
                walk(value, dotted + ".", depth + 1)
            else:
                lines.append(f"{indent}{key}: {_value(value)}")

    walk(OmegaConf.to_container(cfg, resolve=False), "", 0)
    return "\n".join(lines)


def _experiment_file(name: str) -> dict:
    path = files(CONFIG_MODULE).joinpath("experiment", f"{name}.yaml")
    return yaml.safe_load(path.read_text()) or {}


def experiment_length(name: str) -> int:
    """train.presentations of ``experiment=name``: its file's, else that of the experiment it
    extends (its defaults list), else the schema's."""
    data = _experiment_file(name)
    presentations = (data.get("train") or {}).get("presentations")
    if presentations is not None:
        return int(presentations)
    for entry in data.get("defaults") or []:
        if isinstance(entry, str) and not entry.startswith(("override", "/")) and entry != "_self_":
            return experiment_length(entry)
    return schema.TrainConfig.presentations


def experiments() -> list[tuple[str, int]]:
    """Every experiment of conf/experiment/ and its train.presentations."""
    folder = files(CONFIG_MODULE).joinpath("experiment")
    names = sorted(f.name[:-5] for f in folder.iterdir() if f.name.endswith(".yaml"))
    return [(name, experiment_length(name)) for name in names]


def help_text(cfg: DictConfig, overrides: Sequence[str] = ()) -> str:
    """The whole of `parallax-train --help` for this command line's ``cfg``."""
    default = schema.TrainConfig.presentations
    rows = experiments()
    quick = dict(rows).get("quickstart")
    width = max(len(name) for name, _ in rows)
    listing = [f"  {name:<{width}}  {n:>6,} presentations" for name, n in rows]
    given = " ".join(overrides) or "(none)"
    return "\n".join(
        [
            "parallax-train: a simulated HOAP-3 robot learns distance from eye pursuit and motion "
            "parallax.",
            "Whole set-ups: experiment=NAME (conf/experiment/, below); every setting, its type and "
            "default: parallax/config/schema.py.",
            "",
            f"A plain `parallax-train` trains our recipe for {default:,} presentations: hours on a "
            "CPU (docs/performance.md).",
            f"For a first run: parallax-train experiment=quickstart ({quick:,} presentations)."
            if quick
            else "",
            "",
            "== Experiments: experiment=NAME (conf/experiment/) ==",
            *listing,
            "",
            "== Configuration groups: group=option ==",
            config_groups(),
            "",
            f"== Settings: KEY=VALUE; the values of this command line ({given}) ==",
            annotated(cfg),
            "",
            "Hydra's own options: parallax-train --hydra-help",
        ]
    )
