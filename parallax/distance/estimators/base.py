"""The distance estimator's interface: what answers s → d (§3.5), from the learner's queue S.

The distance learner (:class:`parallax.distance.DistanceLearner`) keeps the queue S of the last
c vectors with their targets (eq. 9) and fits its network to it; the run's estimator (one of
this package's files, distance.estimator) is what reads a distance from a new s: the network
itself, as in the paper, or another estimator fitted to the same queue.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

from torch import Tensor


class DistanceEstimator(ABC):
    """Reads distances from vectors s for a distance learner; a subclass in a file of this
    package is found by its ``name`` (the value of distance.estimator)."""

    #: The value of distance.estimator that chooses it.
    name: ClassVar[str]
    #: Whether it is the paper's estimator (listed first).
    paper: ClassVar[bool] = False

    def __init__(self, learner) -> None:  # type: ignore[no-untyped-def]
        """``learner``: the :class:`~parallax.distance.DistanceLearner` whose queue (and
        network) it reads; asked only once the learner has fitted (``learner.is_ready``)."""
        self.learner = learner

    @abstractmethod
    def predict(self, inputs: Tensor) -> Tensor:
        """(n, r) float64 pans (deg), on the learner's device → (n,) distances in the unit of
        the learner's targets (metres)."""
