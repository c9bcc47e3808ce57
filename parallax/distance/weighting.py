"""Sensitive lateral positions and their input weights, paper §3.5.1, eqs. (10)–(12), Table 1.

A lateral position is sensitive when its disparity score at the nearest distance (Table 1) is
larger than or approximately equal to the effective patch size P_e = P_l·√P_s (eq. 10, ≈ 28.3
px for the coarse scale); every position after the first sensitive one is sensitive too. Row k
of S is scaled by w_k = 1/((1 + l_r − l_k)·y) for sensitive k (lengths in cm, the paper's
units) and by 1 otherwise (eq. 12; the printed eq. 11 repeats w_1 in some columns by mistake).

"Approximately equal" is decided by ``tolerance`` in pixels: score ≥ P_e − tolerance. The
default 2.5 px makes 15 cm sensitive (exact score 531·0.15/3 = 26.55, Table 1's 27) while 14 cm
(24.78) and 13 cm (23.01, Table 1's 23) are not; any tolerance in [1.73, 3.50) does the same.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from parallax.geometry import (
    FOCAL_LENGTH_PX,
    NEAREST_DISTANCE_M,
    disparity_score,
    effective_patch_size,
)

CM_PER_M = 100.0


def sensitive_positions(
    lateral_positions_m: Sequence[float],
    *,
    patch: int = 10,
    subsample: float = 8.0,
    nearest_distance: float = NEAREST_DISTANCE_M,
    tolerance: float = 2.5,
    focal_px: float = FOCAL_LENGTH_PX,
) -> list[bool]:
    """For each l_k (metres, in the order of L): is it sensitive (eq. 10 and the text after)?"""
    if not math.isfinite(tolerance) or tolerance < 0:
        raise ValueError(
            f"sensitivity tolerance must be a finite number of pixels ≥ 0, got {tolerance!r}"
        )
    if patch <= 0 or subsample <= 0:
        raise ValueError(
            f"patch and subsample must be positive, got patch={patch!r}, subsample={subsample!r}"
        )
    threshold = effective_patch_size(patch, subsample) - tolerance
    sensitive: list[bool] = []
    for lateral in lateral_positions_m:
        score = disparity_score(float(lateral), nearest_distance, focal_px)
        sensitive.append(bool(sensitive and sensitive[-1]) or score >= threshold)
    return sensitive


def position_weights(
    lateral_positions_m: Sequence[float], sensitive: Sequence[bool], y: float
) -> list[float]:
    """w_k of eq. (12): 1/((1 + l_r − l_k)·y) with l in cm for sensitive positions, else 1."""
    if len(sensitive) != len(lateral_positions_m):
        raise ValueError(
            f"got {len(sensitive)} sensitivity flags for {len(lateral_positions_m)} positions"
        )
    if not math.isfinite(y) or y <= 0:
        raise ValueError(f"weighting hyper-parameter y must be positive and finite, got {y!r}")
    last_cm = float(lateral_positions_m[-1]) * CM_PER_M
    weights = []
    for lateral, is_sensitive in zip(lateral_positions_m, sensitive):
        if not is_sensitive:
            weights.append(1.0)
            continue
        denominator = (1.0 + last_cm - float(lateral) * CM_PER_M) * y
        if not denominator > 0:
            raise ValueError(
                f"weight of lateral position {lateral!r} m is undefined: 1 + l_r − l_k "
                f"= {denominator / y!r} cm must be positive (is L in increasing order?)"
            )
        weights.append(1.0 / denominator)
    return weights
