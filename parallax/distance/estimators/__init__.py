"""Distance estimators (§3.5): what reads a distance from s, fitted to the learner's queue S.

One class per file (:class:`~parallax.distance.estimators.base.DistanceEstimator`), found by
its name: the values of distance.estimator are the names in ``ESTIMATORS``.
"""

from parallax.distance.estimators.base import DistanceEstimator
from parallax.registry import discover

#: distance.estimator's value → its estimator, one per file of this package.
ESTIMATORS: dict[str, type[DistanceEstimator]] = discover(__name__, __path__, DistanceEstimator)

__all__ = ["ESTIMATORS", "DistanceEstimator"]
