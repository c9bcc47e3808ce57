"""One line for a command line whose overrides cannot make a run: the override it is about
and what is wrong, from Hydra's and OmegaConf's longer messages or from :func:`validate`.
`parallax-train` and `parallax-bench` check their overrides with it before anything is
written."""

from __future__ import annotations

import re
from collections.abc import Sequence

from hydra.errors import HydraException
from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from parallax.checks import ConfigError
from parallax.config.plumbing import closest_key, compose, without_hydra
from parallax.config.schema import SCHEMA_NODE
from parallax.config.validate import validate


def _first_line(exc: BaseException | None) -> str:
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def explain(exc: BaseException, overrides: Sequence[str]) -> str:
    """One line for a Hydra composition error: the override it is about and what is wrong."""
    text, first = str(exc), _first_line(exc)
    merging = re.match(r"Error merging override (.+)", first)
    if merging:
        return f"{merging.group(1)}: {_first_line(exc.__cause__)}"
    unknown = re.match(r"Could not override '(.+)'\.", first)
    if unknown:
        key = unknown.group(1)
        given = next((o for o in overrides if o.split("=", 1)[0] == key), key)
        close = closest_key(key)
        return f"{given}: no such setting" + (f"; did you mean {close}?" if close else "")
    missing = re.match(r"In '.+': Could not find '(.+)/([^/]+)'", first)
    if missing:
        group, option = missing.groups()
        listed = text.split("Available options in", 1)[-1].split("Config search path", 1)[0]
        options = [o.strip() for o in listed.splitlines()[1:] if o.strip()]
        options = [o for o in options if o != SCHEMA_NODE] or ["(none)"]
        return f"{group}={option}: no such choice; {group} has {', '.join(options)}"
    if first.startswith("Ambiguous value for argument"):
        given = first[len("Ambiguous value for argument ") :].strip("'")
        return f"{given}: add -m to sweep over its values, or write a list as key=[a,b]"
    return first


def parse_error(overrides: Sequence[str]) -> str | None:
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    for override in overrides:
        try:
            parser.parse_override(override)
        except HydraException as exc:
            return f"{override}: cannot be parsed ({_first_line(exc)})"
    return None


def composed(
    overrides: list[str], check: bool, with_hydra: bool = False
) -> tuple[DictConfig | None, str | None]:
    """The configuration for these overrides, composed (with Hydra's node if ``with_hydra``)
    and, if ``check``, validated, and None; or None and the error line."""
    try:
        cfg = compose(overrides, with_hydra=with_hydra)
        if check:
            validate(without_hydra(cfg) if with_hydra else cfg)
    except ConfigError as exc:
        return None, str(exc)
    except (HydraException, OmegaConfBaseException) as exc:
        return None, explain(exc, overrides)
    return cfg, None


def composition_error(overrides: list[str], check: bool) -> str | None:
    """The error line for these overrides, or None: composed and, if ``check``, validated."""
    return composed(overrides, check)[1]
