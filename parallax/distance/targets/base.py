"""The target source's interface: where the distance learner's targets come from (paper §3.5).

A source turns a *reading* into the target the network learns (the supervisor's reading is the
distance, odometry's the strides walked), says what a perfect learner would answer (the
yardstick of the errors) and takes the learner's step after each sweep: whatever it needs to
read (a walk to the panel), then the online step of :mod:`parallax.distance.online`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from torch import Tensor


class TargetSource(ABC):
    """Turns an observation (s, reading) into the target the network learns; a subclass in a file
    of this package is found by its ``name`` (the value of distance.targets)."""

    #: The value of distance.targets that chooses it.
    name: ClassVar[str]
    #: Whether it is the paper's source (listed first).
    paper: ClassVar[bool] = False
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

    @abstractmethod
    def learn(
        self, learner, tracker, pans: np.ndarray, distances: np.ndarray, bodies: Any
    ) -> tuple[dict[str, float], Any]:  # type: ignore[no-untyped-def]
        """The learner's step after a sweep whose vectors are the rows of ``pans``, panels at
        ``distances``; ``bodies`` has the robots' ``worlds`` and ``walkers`` (parallax.parts.
        Parts). The fit's statistics ({} if none) and what the step recorded (None: nothing)."""

    def truths(self, distances: np.ndarray, bodies: Any) -> np.ndarray:
        """What a perfect learner answers for panels at ``distances`` (``bodies``: as for
        :meth:`learn`)."""
        return np.asarray(distances, dtype=np.float64)

    def state_dict(self) -> dict[str, object]:
        return {}

    def load_state_dict(self, state: dict[str, object]) -> None:
        del state
