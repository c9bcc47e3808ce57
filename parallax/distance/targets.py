"""Where the distance learner's targets come from, paper §3.5 ("human supervision").

The paper trains on ground-truth distances given by a supervisor. Target sources are looked up
by name in ``TARGET_SOURCES`` so that another source (e.g. a self-supervised one) can be added
with ``@register_target_source("name")`` without touching the learner.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable

from torch import Tensor

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
    """Turns an observation (s, ground-truth distance) into the target the network learns."""

    @abstractmethod
    def __call__(self, s: Tensor, distance_m: float) -> float:
        """The target distance in metres for eye-movement vector ``s``."""

    def state_dict(self) -> dict[str, object]:
        return {}

    def load_state_dict(self, state: dict[str, object]) -> None:
        del state


@register_target_source("ground_truth")
class GroundTruthTargets(TargetSource):
    """The simulator's true distance, as the paper's supervisor provides it."""

    def __call__(self, s: Tensor, distance_m: float) -> float:
        distance_m = float(distance_m)
        if not math.isfinite(distance_m) or distance_m <= 0:
            raise ValueError(
                "ground-truth distance must be a positive finite number of metres, "
                f"got {distance_m!r}"
            )
        return distance_m


def make_target_source(spec: str | TargetSource) -> TargetSource:
    """A registered source by name, or ``spec`` itself if it already is a source."""
    if isinstance(spec, TargetSource):
        return spec
    if spec not in TARGET_SOURCES:
        raise ValueError(f"unknown target source {spec!r}; registered: {sorted(TARGET_SOURCES)}")
    return TARGET_SOURCES[spec]()
