"""The paper's targets (§3.5, "human supervision"): the supervisor gives each panel's distance."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from torch import Tensor

from parallax.distance.online import learn_online
from parallax.distance.targets.base import TargetSource


class SupervisorTargets(TargetSource):
    """The simulator's true distance, as the paper's supervisor provides it."""

    name = "supervisor"
    paper = True

    def __call__(self, s: Tensor, reading: float) -> float:
        distance_m = float(reading)
        if not math.isfinite(distance_m) or distance_m <= 0:
            raise ValueError(
                f"the supervisor's distance must be a positive finite number of metres, "
                f"got {distance_m!r}"
            )
        return distance_m

    def learn(
        self, learner, tracker, pans: np.ndarray, distances: np.ndarray, bodies: Any
    ) -> tuple[dict[str, float], None]:  # type: ignore[no-untyped-def]
        """Learn one presentation's vectors with their panels' distances; no walks."""
        return learn_online(learner, tracker, pans, distances), None
