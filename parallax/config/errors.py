"""The error a configuration value that cannot work raises: one line naming the key and value."""

from __future__ import annotations

import math
from typing import Any

from hydra.errors import CompactHydraException
from omegaconf import Container, OmegaConf


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
