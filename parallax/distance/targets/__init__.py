"""Where the distance learner's targets come from (paper §3.5; beyond it, §7).

One source per file (:class:`~parallax.distance.targets.base.TargetSource`), found by its name:
the values of distance.targets are the names in ``TARGET_SOURCES``; ``supervisor`` is the
paper's, ``odometry`` the robot's own walk.
"""

from __future__ import annotations

from collections.abc import Mapping

from parallax.distance.targets.base import TargetSource
from parallax.distance.targets.odometry import OdometryConfig, OdometryTargets
from parallax.distance.targets.supervisor import SupervisorTargets
from parallax.registry import discover

#: distance.targets's value → its source, one per file of this package.
TARGET_SOURCES: dict[str, type[TargetSource]] = discover(__name__, __path__, TargetSource)


def make_target_source(
    spec: str | TargetSource, odometry: Mapping[str, float] | None = None
) -> TargetSource:
    """A source by name (distance.targets; a walking source with the ``odometry`` options), or
    ``spec`` itself if it already is a source."""
    if isinstance(spec, TargetSource):
        return spec
    cls = TARGET_SOURCES[spec]
    return cls(**(odometry or {})) if cls.walks else cls()


__all__ = [
    "TARGET_SOURCES",
    "OdometryConfig",
    "OdometryTargets",
    "SupervisorTargets",
    "TargetSource",
    "make_target_source",
]
