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

from collections.abc import Sequence

from parallax.distance.settings import SensitivityConfig
from parallax.geometry import FOCAL_LENGTH_PX, disparity_score, effective_patch_size

CM_PER_M = 100.0


def sensitive_positions(
    lateral_positions_m: Sequence[float],
    *,
    patch: int = SensitivityConfig.patch,
    subsample: float = SensitivityConfig.subsample,
    nearest_distance: float = SensitivityConfig.nearest_distance,
    tolerance: float = SensitivityConfig.tolerance,
    focal_px: float = FOCAL_LENGTH_PX,
) -> list[bool]:
    """For each l_k (metres, in the order of L): is it sensitive (eq. 10 and the text after)?
    The settings are distance.sensitivity's (parallax.config checks their ranges)."""
    threshold = effective_patch_size(patch, subsample) - tolerance
    sensitive: list[bool] = []
    for lateral in lateral_positions_m:
        score = disparity_score(float(lateral), nearest_distance, focal_px)
        sensitive.append(bool(sensitive and sensitive[-1]) or score >= threshold)
    return sensitive


def position_weights(
    lateral_positions_m: Sequence[float], sensitive: Sequence[bool], y: float
) -> list[float]:
    """w_k of eq. (12): 1/((1 + l_r − l_k)·y) with l in cm for sensitive positions, else 1; L
    increasing and y > 0 (curriculum.lateral_positions and distance.y, checked by
    parallax.config)."""
    if len(sensitive) != len(lateral_positions_m):
        raise ValueError(
            f"got {len(sensitive)} sensitivity flags for {len(lateral_positions_m)} positions"
        )
    last_cm = float(lateral_positions_m[-1]) * CM_PER_M
    weights = []
    for lateral, is_sensitive in zip(lateral_positions_m, sensitive):
        if not is_sensitive:
            weights.append(1.0)
            continue
        weights.append(1.0 / ((1.0 + last_cm - float(lateral) * CM_PER_M) * y))
    return weights
