"""Egocentric distance representation, paper §3.5–3.5.2, eqs. (9)–(15), Fig. 6.

``DistanceLearner`` wires the queue memory (eq. 9), the sensitive-position weighting
(eqs. 10–12), the MLP (eqs. 13–15) and the Levenberg–Marquardt optimiser; ``metrics`` holds
the per-range distance error of Tables 4–5.
"""

from parallax.distance.learner import DistanceLearner
from parallax.distance.levenberg_marquardt import LevenbergMarquardt, LMRunResult, LMStepResult
from parallax.distance.metrics import distance_error_by_range
from parallax.distance.network import DistanceMLP
from parallax.distance.queue_memory import QueueMemory
from parallax.distance.targets import (
    TARGET_SOURCES,
    OdometryTargets,
    SupervisorTargets,
    TargetSource,
)
from parallax.distance.weighting import position_weights, sensitive_positions

__all__ = [
    "DistanceLearner",
    "DistanceMLP",
    "OdometryTargets",
    "SupervisorTargets",
    "LMRunResult",
    "LMStepResult",
    "LevenbergMarquardt",
    "QueueMemory",
    "TARGET_SOURCES",
    "TargetSource",
    "distance_error_by_range",
    "position_weights",
    "sensitive_positions",
]
