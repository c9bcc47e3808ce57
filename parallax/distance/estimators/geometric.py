"""Beyond the paper: the distance from the geometry of pursuit, a linear model of 1/d on tan q_p.

An eye that holds the panel's centre from the lateral offset l_p turns to q_p = atan(l_p/d), so
tan q_p = l_p/d and 1/d is linear in every tan q_p. This estimator fits that line, weights on
[tan q_1 … tan q_r, 1], to the distance learner's queue S (eq. 9) by weighted least squares,
each row weighted by d² so that the fit minimises the relative error of Tables 4–5 (the movement
planner's fit, :mod:`parallax.distance.inverse_distance`, on the tangents of the pans), and
answers 1/(w·[tan s, 1]) within the distances of the queue: a line, unlike the network's
sigmoids, runs off without bound for a vector unlike the queue's (an eye that ran away), and a
distance beyond those it has learnt is not one it can vouch for. It refits whenever the queue has
changed; the learner's network is fitted as before, but no longer asked.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from parallax.distance.estimators.base import DistanceEstimator
from parallax.distance.inverse_distance import InverseDistanceFit, fit_inverse_distance

#: Added to the Gram matrix's diagonal, as the planner does: it keeps the fit of r nearly
#: collinear tangents invertible without moving it.
RIDGE = 1.0e-6


class Geometric(DistanceEstimator):
    """Weighted least squares of 1/d on [tan s, 1] over the learner's queue, its answers within
    the queue's distances."""

    name = "geometric"

    def __init__(self, learner) -> None:  # type: ignore[no-untyped-def]
        super().__init__(learner)
        self.fit: InverseDistanceFit | None = None
        self.fitted_at = -1  # the learner's observations when the fit was made
        self.nearest = self.farthest = 0.0  # the queue's distances then

    def predict(self, inputs: Tensor) -> Tensor:
        if self.fit is None or self.fitted_at != self.learner.observations:
            queue = self.learner.queue
            tangents = np.tan(np.radians(queue.inputs.cpu().numpy()))
            targets = queue.targets.cpu().numpy()
            self.fit = fit_inverse_distance(tangents, targets, RIDGE)
            self.fitted_at = self.learner.observations
            self.nearest, self.farthest = float(targets.min()), float(targets.max())
        estimates = self.fit.estimate(np.tan(np.radians(inputs.cpu().numpy())))
        estimates = np.clip(estimates, self.nearest, self.farthest)
        return torch.as_tensor(estimates, dtype=torch.float64, device=inputs.device)
