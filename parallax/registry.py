"""Strategies found by their files: every class of a package's modules that names itself.

A part that has interchangeable strategies (the pan readouts of :mod:`parallax.readouts`, the
distance estimators of :mod:`parallax.distance.estimators`, the target sources of
:mod:`parallax.distance.targets`) keeps one class per file; its package asks :func:`discover`
for them, so adding a strategy is adding its file, and the allowed values of its setting are
the names found.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterable


def discover(package: str, paths: Iterable[str], base: type) -> dict[str, type]:
    """Name → class for every subclass of ``base`` with a ``name`` defined in the modules of
    ``package`` (found at ``paths``, the package's ``__path__``): the paper's own first (a class
    whose ``paper`` is true), then the others in their modules' order."""
    found: dict[str, type] = {}
    for module in sorted(info.name for info in pkgutil.iter_modules(list(paths))):
        loaded = importlib.import_module(f"{package}.{module}")
        for value in vars(loaded).values():
            named = isinstance(value, type) and issubclass(value, base) and value is not base
            if named and value.__module__ == loaded.__name__ and "name" in vars(value):
                if value.name in found:
                    raise ValueError(f"two {base.__name__}s are named {value.name!r}")
                found[value.name] = value
    return dict(sorted(found.items(), key=lambda item: not getattr(item[1], "paper", False)))
