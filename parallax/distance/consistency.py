"""Which queued eye-movement vectors agree with their neighbours — beyond the paper (§3.5).

The paper fits the distance network on every vector s of the queue S (eq. 9). A pursuit that
ran away (the eye drifting degrees past the target, which our runs show in 10–20 % of trials)
gives an s far from the vectors queued for nearby distances, and one such vector in a small
queue bends the LM fit for every distance around it (docs/results/notes.md).

The check uses only what the learner already holds: for each queued (s, d), the reference is
the per-position median of the ``neighbours`` other queued vectors whose target distances are
nearest d; its deviation is the mean over positions of |s − reference| in degrees. A vector is
an outlier when its deviation exceeds the median deviation of the queue by more than
``mads`` scaled median absolute deviations. Nothing is dropped from the queue: the mask is
recomputed at every fit, so once the eye movements change for good (after §5's perturbation)
the new vectors become the majority of their neighbourhoods and are used again.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

#: 1.4826·MAD estimates the standard deviation of normally distributed deviations.
MAD_TO_SD = 1.4826


def check_settings(mads: float | None, neighbours: int) -> None:
    """Raise a one-line ValueError for a threshold or neighbourhood that cannot work."""
    if mads is not None and not (math.isfinite(float(mads)) and float(mads) > 0):
        raise ValueError(
            f"outlier_mads must be a positive number of MADs or null (off), got {mads!r}"
        )
    if int(neighbours) != neighbours or neighbours < 2:
        raise ValueError(f"outlier_neighbours must be an integer ≥ 2, got {neighbours!r}")


def neighbour_deviation(inputs: Tensor, targets: Tensor, neighbours: int) -> Tensor:
    """(n,) mean |s − median of the nearest-target neighbours' s| per queued vector, in degrees.

    Ties in target distance are broken by queue order (newest first), so the result does not
    depend on anything but the queue.
    """
    count = inputs.shape[0]
    k = min(int(neighbours), count - 1)
    gaps = (targets[:, None] - targets[None, :]).abs()
    gaps.fill_diagonal_(math.inf)  # a vector is not its own neighbour
    # a stable sort keeps queue order among equal gaps (argsort alone does not promise it)
    nearest = torch.sort(gaps, dim=1, stable=True).indices[:, :k]
    reference = inputs[nearest].median(dim=1).values
    return (inputs - reference).abs().mean(dim=1)


def consistent_mask(inputs: Tensor, targets: Tensor, mads: float, neighbours: int = 8) -> Tensor:
    """(n,) bool: True for the queued vectors the fit should use (see the module docstring).

    Queues of fewer than ``neighbours`` + 2 vectors, or whose deviations have no spread, are
    used whole.
    """
    count = inputs.shape[0]
    if count < int(neighbours) + 2:
        return torch.ones(count, dtype=torch.bool, device=inputs.device)
    deviation = neighbour_deviation(inputs, targets, neighbours)
    centre = deviation.median()
    spread = MAD_TO_SD * (deviation - centre).abs().median()
    if not bool(spread > 0):
        return torch.ones(count, dtype=torch.bool, device=inputs.device)
    return deviation <= centre + float(mads) * spread
