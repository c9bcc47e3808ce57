"""Beyond the paper: the inverse distance as a weighted least-squares fit on a trial's pans.

A pan that holds the panel's centre is atan(l/d), small at l ≤ 20 cm and d ≥ 3 m, so a linear
function of the pans (or of their tangents, l/d exactly) predicts 1/d. Weighting each row by d²
makes the fit minimise the relative error |d̂ − d|/d, the measure of Tables 4–5. The movement
planner (§7, :mod:`parallax.distance.planner`) fits one per subset of L it may visit; a
distance estimator (:mod:`parallax.distance.estimators`) may fit one on the learner's queue.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class InverseDistanceFit:
    """Weights on [x, 1] for the inverse distance, and the fit's leave-one-out estimates and
    relative errors (%) on the rows it was fitted to."""

    weights: np.ndarray
    loo_estimates: np.ndarray
    loo_errors_pct: np.ndarray

    def estimate(self, x: np.ndarray) -> np.ndarray:
        """Distances (m) for the rows of ``x`` (n, k), without the column of ones."""
        ones = np.ones((*x.shape[:-1], 1))
        return 1.0 / np.maximum(np.concatenate([x, ones], axis=-1) @ self.weights, 1e-9)


def fit_inverse_distance(x: np.ndarray, distances: np.ndarray, ridge: float) -> InverseDistanceFit:
    """The fit of 1/d on [x, 1] (``x``: (n, k) float64), weighted by d², with ``ridge`` added to
    the Gram matrix's diagonal so that it stays invertible."""
    x = np.concatenate([x, np.ones((distances.size, 1))], axis=1)
    y, w = 1.0 / distances, distances**2
    gram = x.T @ (x * w[:, None]) + ridge * np.eye(x.shape[1])
    inverse = np.linalg.inv(gram)
    weights = inverse @ (x.T @ (w * y))
    # leave-one-out residuals of weighted least squares: e_i / (1 − h_ii)
    leverage = np.einsum("ij,jk,ik->i", x, inverse, x) * w
    residual = (y - x @ weights) / np.maximum(1.0 - leverage, 1e-9)
    loo_inverse = np.maximum(y - residual, 1e-9)
    loo = 1.0 / loo_inverse
    return InverseDistanceFit(weights, loo, 100.0 * np.abs(loo - distances) / distances)
