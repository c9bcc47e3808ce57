"""Viewing geometry shared by the world and the distance learner (paper §3.5.1, Table 1).

The disparity score is the horizontal shift, in pixels, of the stimulus between the reference
image I0 (taken at l0) and the first image at lateral position l, before any eye movement:
score = f·l/d. The camera's focal length is chosen so that the paper's Table 1 follows from it
at d = 3 m: round(531·l/3) = 9, 12, 18, 23, 27, 35 px for l = 5, 7, 10, 13, 15, 20 cm.

The eye's action set A (§3.4) is here too, the one constant that the world, the policy and the
schema share.
"""

from __future__ import annotations

import math

#: The paper's action set A: pan increments in degrees per iteration (§3.4).
ACTION_SET_DEG = (-0.2, -0.1, -0.05, 0.0, 0.05, 0.1, 0.2)

#: Focal length of the eye cameras in pixels (for every image size; see ``parallax.envs``).
FOCAL_LENGTH_PX = 531.0

#: The nearest distance of the paper's grid, where the disparity is largest (Table 1).
NEAREST_DISTANCE_M = 3.0


def disparity_score(
    lateral_m: float, distance_m: float = NEAREST_DISTANCE_M, focal_px: float = FOCAL_LENGTH_PX
) -> float:
    """Disparity f·l/d in pixels of a lateral move ``lateral_m`` at ``distance_m`` (Table 1)."""
    if not math.isfinite(distance_m) or distance_m <= 0:
        raise ValueError(f"distance must be a positive finite number of metres, got {distance_m!r}")
    return focal_px * abs(lateral_m) / distance_m


def effective_patch_size(patch_px: int = 10, subsample: float = 8.0) -> float:
    """Effective patch size P_e = P_l·√P_s, eq. (10): ≈ 28 px for the coarse scale."""
    return patch_px * math.sqrt(subsample)
