"""The paper's estimator (§3.5.2, eqs. 13–15): the learner's MLP on the weighted pans."""

from __future__ import annotations

import torch
from torch import Tensor

from parallax.distance.estimators.base import DistanceEstimator


class Network(DistanceEstimator):
    """The network the learner fits by Levenberg–Marquardt, on s weighted as in training
    (eqs. 10–12)."""

    name = "network"
    paper = True

    def predict(self, inputs: Tensor) -> Tensor:
        with torch.no_grad():
            return self.learner.network(inputs * self.learner.weights)
