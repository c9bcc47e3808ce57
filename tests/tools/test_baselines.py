"""The distance-blind baselines of the eye-movement MAE (parallax.tools.analysis.baselines)."""

from __future__ import annotations

import math

import numpy as np

from parallax.tools.analysis.baselines import constant_pan_baselines, target_pans


def test_target_pans_follow_the_viewing_geometry():
    distances = [3.0, 6.5, 10.0]
    pans = target_pans(0.2, distances)
    # the pan axis sits ~6.5 cm behind the eye: α* ≈ atan(l / (d + 0.065)) within 0.02°
    approx = [math.degrees(math.atan(0.2 / (d + 0.065))) for d in distances]
    np.testing.assert_allclose(pans, approx, atol=0.02)


def test_the_best_constant_pan_beats_standing_still_and_grows_with_l():
    b = constant_pan_baselines([0.05, 0.2], distances=[3.0, 4.0, 5.0, 7.0, 10.0])
    assert b["5"]["best_constant"] < b["5"]["pan_zero"]
    assert b["20"]["best_constant"] > b["5"]["best_constant"]
    # the best constant pan is the median α*, which for 5 distances is α*(5 m)
    assert b["20"]["best_constant_pan"] == target_pans(0.2, [5.0])[0]
