"""Where the distance learner's targets come from: paper §3.5 ("human supervision") and, beyond
the paper, §7's second future work (distance from the robot's own body).

``supervisor``: the true distances, handed over as the paper's supervisor does. ``odometry``: the
robot walks to the panel until it touches it (parallax.envs.walk) and its target is the strides
it counted times the stride it believes it has — its body's unit, not the supervisor's. A source
turns a *reading* into a target: the supervisor's reading is the distance, odometry's the
strides walked. Sources are looked up by name in ``TARGET_SOURCES``; another one is added with
``@register_target_source("name")`` without touching the learner.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

from torch import Tensor


@dataclass
class OdometryConfig:
    """The robot's own measure of distance for distance.targets=odometry: strides counted on
    a walk to the panel (env.walk) times the stride length it believes it has."""

    #: Fraction of presentations that end with a walk (walking is costly); the others give the
    #: learner no target and are only predicted.
    walk_fraction: float = 1.0
    #: The stride length the robot believes it has (m): its unit of distance.
    nominal_stride_m: float = 0.05


TARGET_SOURCES: dict[str, type[TargetSource]] = {}


def register_target_source(name: str) -> Callable[[type[TargetSource]], type[TargetSource]]:
    """Class decorator adding a target source to ``TARGET_SOURCES`` under ``name``."""

    def register(cls: type[TargetSource]) -> type[TargetSource]:
        if name in TARGET_SOURCES:
            raise ValueError(f"target source {name!r} is already registered")
        TARGET_SOURCES[name] = cls
        return cls

    return register


class TargetSource(ABC):
    """Turns an observation (s, reading) into the target the network learns."""

    #: Whether a reading needs the robot to walk to the panel (env.walk) after its sweep.
    walks: bool = False
    #: The fraction of presentations that end with a walk (those that do not get no target).
    walk_fraction: float = 1.0

    @abstractmethod
    def __call__(self, s: Tensor, reading: float) -> float:
        """The target for eye-movement vector ``s`` from this source's ``reading``."""

    def truth(self, distance_m: float, walk_length_strides: float) -> float:
        """What a perfect learner would answer for a panel at ``distance_m`` that the body,
        as it is now, reaches in ``walk_length_strides`` of its true strides: the yardstick of
        the error statistics (never a target)."""
        del walk_length_strides
        return float(distance_m)

    def state_dict(self) -> dict[str, object]:
        return {}

    def load_state_dict(self, state: dict[str, object]) -> None:
        del state


@register_target_source("supervisor")
class SupervisorTargets(TargetSource):
    """The simulator's true distance, as the paper's supervisor provides it."""

    def __call__(self, s: Tensor, reading: float) -> float:
        distance_m = float(reading)
        if not math.isfinite(distance_m) or distance_m <= 0:
            raise ValueError(
                f"the supervisor's distance must be a positive finite number of metres, "
                f"got {distance_m!r}"
            )
        return distance_m


@register_target_source("odometry")
class OdometryTargets(TargetSource):
    """Strides walked to touch the panel × the stride the robot believes it has (metres of its
    own): the embodied meaning of "how far" (§7). A growth spurt changes the true stride, not
    this one, so the targets follow the body."""

    walks = True

    def __init__(
        self,
        walk_fraction: float = OdometryConfig.walk_fraction,
        nominal_stride_m: float = OdometryConfig.nominal_stride_m,
    ) -> None:
        self.walk_fraction = float(walk_fraction)
        self.nominal_stride_m = float(nominal_stride_m)

    def __call__(self, s: Tensor, reading: float) -> float:
        strides = float(reading)
        if not math.isfinite(strides) or strides <= 0:
            raise ValueError(f"a walk's stride count must be positive and finite, got {strides!r}")
        return strides * self.nominal_stride_m

    def truth(self, distance_m: float, walk_length_strides: float) -> float:
        del distance_m
        return float(walk_length_strides) * self.nominal_stride_m


def make_target_source(
    spec: str | TargetSource, odometry: dict[str, float] | None = None
) -> TargetSource:
    """A registered source by name (distance.targets; the odometry source with the ``odometry``
    options), or ``spec`` itself if it already is a source."""
    if isinstance(spec, TargetSource):
        return spec
    cls = TARGET_SOURCES[spec]
    return cls(**(odometry or {})) if cls.walks else cls()
