"""What every part's settings (its ``settings.py``) are checked with, below all of them.

Each part keeps its settings beside their checks: a dataclass per config node with every
setting's type and one default, the allowed values of its choices, and a ``check(check)`` that
reads the composed config through a :class:`Checks` and raises :class:`ConfigError`, one line
naming the first key and value that cannot work. :mod:`parallax.config` gathers them; a
component's keyword defaults come from its node through :func:`default`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

from hydra.errors import CompactHydraException
from omegaconf import Container, DictConfig, OmegaConf

#: How B robots in lockstep teach the dictionaries (coder.robot_updates) and the policy
#: (policy.robot_updates): each, every robot's update applied as a step of its own | mean, one
#: step, the mean of the robots' updates. Either is the paper's single robot at env.robots=1.
ROBOT_UPDATES = ("each", "mean")


def format_value(value: Any) -> str:
    """A value as it would be written in an override (``null``, ``true``, ``[0.05,0.1]``)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # nan, inf, -inf
    if isinstance(value, Container):
        value = OmegaConf.to_container(value)
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{format_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(format_value(v) for v in value) + "]"
    return str(value)


class ConfigError(ValueError, CompactHydraException):
    """A configuration value that cannot work: ``key=value: reason``.

    A CompactHydraException, so that when a sweep's job raises it Hydra reports this one line
    rather than a traceback.
    """

    def __init__(self, key: str, value: Any, reason: str):
        if isinstance(value, Container):  # plain values pickle and print without OmegaConf
            value = OmegaConf.to_container(value)
        super().__init__(f"{key}={format_value(value)}: {reason}")
        self.key, self.value, self.reason = key, value, reason

    def __reduce__(self):
        # Launchers (joblib, submitit) send a failed job's exception back by pickling it.
        return (type(self), (self.key, self.value, self.reason))


class Checks:
    """Reads values from the config by dotted key and raises ConfigError naming that key."""

    def __init__(self, cfg: DictConfig):
        self.cfg = cfg

    def get(self, key: str) -> Any:
        value = OmegaConf.select(self.cfg, key, throw_on_missing=True)
        return OmegaConf.to_container(value) if OmegaConf.is_config(value) else value

    @staticmethod
    def fail(key: str, value: Any, reason: str) -> None:
        raise ConfigError(key, value, reason)

    def require(self, key: str, wanted: Any, reason: str) -> None:
        """``key`` must be ``wanted`` (another setting's value asks for it: ``reason`` says why)."""
        value = self.get(key)
        if value != wanted:
            self.fail(key, value, reason)

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


def default(node: type, name: str) -> Any:
    """The schema's default of ``node``'s setting ``name``, for a component's keyword default:
    lists as tuples and nodes as read-only mappings, so that one default object can be shared by
    every call. Plain values can be read off the class as well (``CoderConfig.atoms``)."""
    spec = next(spec for spec in dataclasses.fields(node) if spec.name == name)
    value = spec.default_factory() if spec.default is dataclasses.MISSING else spec.default
    return _read_only(value)


def _read_only(value: Any) -> Any:
    if dataclasses.is_dataclass(value):
        value = {spec.name: getattr(value, spec.name) for spec in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return MappingProxyType({key: _read_only(item) for key, item in value.items()})
    if isinstance(value, list):
        return tuple(_read_only(item) for item in value)
    return value
