"""The body's continuous lateral sweep: beyond the paper's pick-and-place (§4.1).

The paper sets the robot down at each position of L and lets it stand for t_h iterations. With
``env.motion=continuous`` the body instead translates from l0 = 0 to the end of L in one trial,
``speed_m`` metres per iteration on average, while the eye acts at every iteration; the pans at
the body offsets of L are read as the body passes them (:class:`parallax.presentation.Tally`).

Two speed profiles: ``constant``, x(t) = min(v·t, l_r); ``smooth``, the minimum-jerk path
x(t) = l_r·(10s³ − 15s⁴ + 6s⁵) with s = t/(T − 1) over the same T iterations (zero speed and
acceleration at both ends; its peak speed is 1.875 times the mean).
"""

from __future__ import annotations

import math

import numpy as np

#: How the body moves between lateral positions: set down at each (the paper), or sweeping.
MOTIONS = ("pick_and_place", "continuous")
#: The continuous sweep's speed over time.
SWEEP_PROFILES = ("constant", "smooth")
#: Peak over mean speed of each profile.
PEAK_OVER_MEAN = {"constant": 1.0, "smooth": 1.875}


def sweep_iterations(end_m: float, speed_m: float) -> int:
    """T, the iterations of a sweep from l0 = 0 to ``end_m`` at a mean ``speed_m`` per iteration:
    the body is at l0 at the first and at ``end_m`` at the last."""
    return math.ceil(end_m / speed_m - 1e-9) + 1


def body_offsets(end_m: float, speed_m: float, profile: str) -> np.ndarray:
    """x(t) for t = 0 … T − 1 (metres), from 0 to ``end_m``."""
    iterations = sweep_iterations(end_m, speed_m)
    t = np.arange(iterations, dtype=np.float64)
    if profile == "constant":
        return np.minimum(t * speed_m, end_m)
    s = t / (iterations - 1)
    return end_m * (10 * s**3 - 15 * s**4 + 6 * s**5)


def fastest_target_pan_deg(speed_m: float, profile: str, nearest_m: float) -> float:
    """The fastest the target's pan α* = atan(l/d) turns during a sweep, degrees per iteration:
    at the peak speed, at the nearest distance (dα*/dl = d/(d² + l²) ≤ 1/d)."""
    return math.degrees(PEAK_OVER_MEAN[profile] * speed_m / nearest_m)


def fastest_followable_speed_m(largest_step_deg: float, profile: str, nearest_m: float) -> float:
    """The mean speed (m per iteration) at which α* turns, at its fastest, by the eye's largest
    step per iteration: beyond it the eye cannot keep up at the nearest distance."""
    return math.radians(largest_step_deg) * nearest_m / PEAK_OVER_MEAN[profile]
