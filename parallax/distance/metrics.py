"""Distance-estimation error per range of distances, paper §6, Tables 4–5.

Error of one estimate: |d̂ − d|/d in percent. Ranges follow the tables' columns on the 0.1 m
grid as half-open bins [3, 5), [5, 7) and [7, 10] m, so 4.95 m falls into "3-4.9". "total" is
the mean over every sample (not the mean of the three ranges): that reproduces the tables'
"Total Average" (e.g. Table 4, 5–20 cm without weighting: (20·6.39 + 20·2.24 + 31·3.06)/71 =
3.77). Distances outside [3, 10] count only in "total"; an empty range gives NaN.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

RANGES: dict[str, tuple[float, float, bool]] = {  # name: (low, high, high included)
    "3-4.9": (3.0, 5.0, False),
    "5-6.9": (5.0, 7.0, False),
    "7-10": (7.0, 10.0, True),
}


def _as_array(values: Sequence[float] | np.ndarray | torch.Tensor) -> np.ndarray:
    if isinstance(values, torch.Tensor):
        values = values.detach().cpu().numpy()
    return np.asarray(values, dtype=np.float64).reshape(-1)


def distance_error_by_range(
    d_hat: Sequence[float] | np.ndarray | torch.Tensor,
    d: Sequence[float] | np.ndarray | torch.Tensor,
    at: Sequence[float] | np.ndarray | None = None,
) -> dict[str, float]:
    """Mean |d̂ − d|/d in percent for "3-4.9", "5-6.9", "7-10" (metres) and "total"; the ranges
    are of ``at`` if given (the panels' distances, when d is in another unit: odometry's)."""
    estimates, truths = _as_array(d_hat), _as_array(d)
    if estimates.shape != truths.shape or truths.size == 0:
        raise ValueError(
            "d_hat and d must be non-empty and of equal length, "
            f"got {estimates.size} and {truths.size}"
        )
    if not np.all(np.isfinite(truths)) or np.any(truths <= 0):
        bad = truths[~np.isfinite(truths) | (truths <= 0)][0]
        raise ValueError(f"true distances must be positive and finite, got {bad!r}")
    errors = 100.0 * np.abs(estimates - truths) / truths
    result: dict[str, float] = {}
    for name, inside in range_masks(truths if at is None else at).items():
        result[name] = float(errors[inside].mean()) if inside.any() else math.nan
    result["total"] = float(errors.mean())
    return result


def range_masks(distances: Sequence[float] | np.ndarray | torch.Tensor) -> dict[str, np.ndarray]:
    """Which of ``distances`` (metres) fall in each of RANGES, as boolean masks."""
    # 3.0 + 20·0.1 may land a hair below 5.0
    grid = np.round(_as_array(distances), 9)
    return {
        name: (grid >= low) & ((grid <= high) if high_included else (grid < high))
        for name, (low, high, high_included) in RANGES.items()
    }
