"""The paper's published numbers (Tables 2–5 of Prucksakorn, Jeong & Chong), as plain data.

Copied digit for digit from `paper.md`: §4.2.2 Table 2 (eye-movement MAE of the last 100 trials,
"Average (Variance)", in degrees), §5 Table 3 (the same after the perturbations: left camera
rotated by 15°, Gaussian blur σ = 2), §6 Tables 4 and 5 (average distance-estimation error in
percent per range of distances, before and after the perturbations). `parallax-report` puts our
numbers beside these; nothing here is computed.
"""

from __future__ import annotations

#: Rows of Tables 2–3: the lateral positions of the single-position runs, in cm (as the labels
#: of `parallax.metrics.position_label`).
TABLE_POSITIONS_CM: tuple[str, ...] = ("5", "7", "10", "13", "15", "20")

#: Columns of Tables 2–3 and the lateral lists L they were trained on (cm). "Sing." is one run
#: per row, trained on that row's position alone.
SINGLE = "Sing."
MULTI_5_10 = "Mult. 5-10 cm"
MULTI_5_20 = "Mult. 5-20 cm"
EYE_MOVEMENT_COLUMNS: tuple[str, ...] = (SINGLE, MULTI_5_10, MULTI_5_20)
MULTI_LISTS_CM: dict[str, tuple[str, ...]] = {
    MULTI_5_10: tuple(str(l) for l in range(5, 11)),
    MULTI_5_20: tuple(str(l) for l in range(5, 21)),
}

#: Table 2: average (variance) of the eye-movement error over the last 100 trials, degrees.
#: None where the paper has "-" (the position is not in that run's list).
TABLE2: dict[str, dict[str, tuple[float, float] | None]] = {
    SINGLE: {
        "5": (0.18, 0.10),
        "7": (0.16, 0.06),
        "10": (0.16, 0.02),
        "13": (0.18, 0.02),
        "15": (0.30, 0.08),
        "20": (0.91, 1.15),
    },
    MULTI_5_10: {
        "5": (0.18, 0.08),
        "7": (0.16, 0.06),
        "10": (0.17, 0.06),
        "13": None,
        "15": None,
        "20": None,
    },
    MULTI_5_20: {
        "5": (0.25, 0.13),
        "7": (0.18, 0.06),
        "10": (0.18, 0.07),
        "13": (0.17, 0.03),
        "15": (0.17, 0.03),
        "20": (0.19, 0.04),
    },
}

#: Table 3: the same after the perturbations were applied and training continued.
TABLE3: dict[str, dict[str, tuple[float, float] | None]] = {
    SINGLE: {
        "5": (0.12, 0.01),
        "7": (0.14, 0.01),
        "10": (0.21, 0.04),
        "13": (0.36, 0.12),
        "15": (0.54, 0.21),
        "20": (1.09, 1.03),
    },
    MULTI_5_10: {
        "5": (0.13, 0.01),
        "7": (0.15, 0.01),
        "10": (0.18, 0.02),
        "13": None,
        "15": None,
        "20": None,
    },
    MULTI_5_20: {
        "5": (0.16, 0.02),
        "7": (0.16, 0.03),
        "10": (0.18, 0.01),
        "13": (0.21, 0.04),
        "15": (0.25, 0.04),
        "20": (0.39, 0.13),
    },
}

#: Columns of Tables 4–5: the keys of `parallax.distance.metrics.distance_error_by_range`.
DISTANCE_RANGES: tuple[str, ...] = ("3-4.9", "5-6.9", "7-10", "total")
DISTANCE_RANGE_TITLES: dict[str, str] = {
    "3-4.9": "3 to 4.9 m",
    "5-6.9": "5 to 6.9 m",
    "7-10": "7 to 10 m",
    "total": "Total average",
}

#: Rows of Tables 4–5: (lateral list L in cm, weighting of eq. 10–12 on).
NO_WEIGHTING_5_10 = "5-10 cm without weighting"
NO_WEIGHTING_5_20 = "5-20 cm without weighting"
WEIGHTING_5_20 = "5-20 cm with weighting"
DISTANCE_ROWS: dict[str, tuple[tuple[str, ...], bool]] = {
    NO_WEIGHTING_5_10: (MULTI_LISTS_CM[MULTI_5_10], False),
    NO_WEIGHTING_5_20: (MULTI_LISTS_CM[MULTI_5_20], False),
    WEIGHTING_5_20: (MULTI_LISTS_CM[MULTI_5_20], True),
}

#: Table 4: average distance-estimation error (%) per range of distances.
TABLE4: dict[str, dict[str, float]] = {
    NO_WEIGHTING_5_10: {"3-4.9": 3.97, "5-6.9": 4.09, "7-10": 4.74, "total": 4.33},
    NO_WEIGHTING_5_20: {"3-4.9": 6.39, "5-6.9": 2.24, "7-10": 3.06, "total": 3.77},
    WEIGHTING_5_20: {"3-4.9": 3.66, "5-6.9": 1.89, "7-10": 2.55, "total": 2.69},
}

#: Table 5: the same after the perturbations.
TABLE5: dict[str, dict[str, float]] = {
    NO_WEIGHTING_5_10: {"3-4.9": 3.95, "5-6.9": 3.52, "7-10": 5.50, "total": 4.48},
    NO_WEIGHTING_5_20: {"3-4.9": 4.30, "5-6.9": 2.76, "7-10": 3.03, "total": 3.31},
    WEIGHTING_5_20: {"3-4.9": 2.29, "5-6.9": 0.98, "7-10": 0.82, "total": 1.30},
}
