"""How small a distance error the paper's own eye errors allow (Tables 2–5, §6, eq. 16).

Tables 2–3 give the eye-movement MAE of eq. 16 (degrees, last 100 trials) per lateral position
of the multi-position runs, before and after the perturbations; Tables 4–5 give their distance
errors. Here the pans are drawn from the geometry, q_p = atan(l_p/d), plus noise whose mean
absolute value is that MAE (Gaussian or Laplace; unlisted positions interpolated linearly), and
the distance comes from the best a learner that knows the geometry could do: the weighted
least-squares nearness 1/d̂ = Σ w_p l_p q_p / Σ w_p l_p², w_p = 1/σ_p². Its error, per range as
`parallax.distance.metrics.distance_error_by_range` averages it, is a floor for the paper's
distance error if the eye's errors were independent from trial to trial. Errors that repeat for
a given photograph and distance could be learnt by the network, which could then go below this
floor: the ratio paper/floor is evidence about the paper's numbers, not proof. The estimator
also ignores that d lies in 3–10 m: one that uses it (the posterior over the grid) is about a
fifth lower for 5-10 cm and a tenth for 5-20 cm, so the floor is approximate.

    python -m parallax.tools.analysis.paper_floor [--samples N] [--seed S] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from parallax.distance.metrics import distance_error_by_range
from parallax.tools.analysis.synthetic_pans import PAPER_DISTANCES_M
from parallax.tools.report import paper_results as paper
from parallax.writable import file_problem

RANGES = ("3-4.9", "5-6.9", "7-10", "total")
NOISE_SHAPES = ("gaussian", "laplace")

#: Eye-movement MAE (degrees) per given lateral position (cm) of the two multi-position runs:
#: paper Table 2 ("before", §4.2.2) and Table 3 ("after" the perturbations, §5). The numbers are
#: those of parallax.tools.report.paper_results, the project's one copy of the paper's tables.
EYE_MAE_DEG: dict[tuple[str, str], dict[int, float]] = {
    (column, when): {int(cm): cell[0] for cm, cell in table[column].items() if cell is not None}
    for when, table in (("before", paper.TABLE2), ("after", paper.TABLE3))
    for column in (paper.MULTI_5_10, paper.MULTI_5_20)
}

#: The run's lateral list L (cm) of each multi-position column (§4.2.1).
LATERAL_LIST_CM: dict[str, list[int]] = {
    column: [int(cm) for cm in cms] for column, cms in paper.MULTI_LISTS_CM.items()
}

#: Distance error (%) per range: paper Table 4 ("before") and Table 5 ("after"), one row per
#: set-up, and the eye column (Tables 2–3) each set-up's pans come from. Tables 2–3 have one
#: 5-20 cm column, so both 5-20 cm set-ups share one floor.
PAPER_DISTANCE_ERROR: dict[str, dict[str, dict[str, float]]] = {
    "before": paper.TABLE4,
    "after": paper.TABLE5,
}
EYE_COLUMN_OF_SETUP: dict[str, str] = {
    paper.NO_WEIGHTING_5_10: paper.MULTI_5_10,
    paper.NO_WEIGHTING_5_20: paper.MULTI_5_20,
    paper.WEIGHTING_5_20: paper.MULTI_5_20,
}


def mae_per_position(given_deg: dict[int, float], lateral_cm: list[int]) -> np.ndarray:
    """The MAE at every position of L, linear in lateral position between the given ones."""
    given = sorted(given_deg)
    return np.interp(lateral_cm, given, [given_deg[cm] for cm in given])


def noise_std(mae: np.ndarray, shape: str) -> np.ndarray:
    """Standard deviation of zero-mean noise whose mean absolute value is ``mae``."""
    return mae * (math.sqrt(math.pi / 2) if shape == "gaussian" else math.sqrt(2))


def estimated_distances(pans_rad: np.ndarray, lateral_m: np.ndarray, std: np.ndarray):
    """Weighted least-squares nearness from q_p ≈ l_p·(1/d), inverted; the weights 1/σ² are
    guarded so that a noiseless eye gives equal weights instead of 0/0."""
    weights = 1.0 / np.maximum(std, 1e-12) ** 2
    nearness = (pans_rad * weights * lateral_m).sum(axis=1) / (weights * lateral_m**2).sum()
    return 1.0 / np.maximum(nearness, 1e-3)  # a pan pointing away would give d < 0


def floor(mae_deg: np.ndarray, lateral_cm: list[int], shape: str, samples: int, rng) -> dict:
    """Mean error (%) per range and in total, and the median, of the estimator on noisy pans."""
    lateral_m = np.asarray(lateral_cm, float) / 100.0
    distances = np.repeat(PAPER_DISTANCES_M, samples)
    std_rad = np.radians(noise_std(np.asarray(mae_deg, float), shape))
    size = (len(distances), len(lateral_m))
    if shape == "gaussian":
        noise = rng.normal(0.0, 1.0, size) * std_rad
    else:  # Laplace with scale b = MAE: std = b·√2
        noise = rng.laplace(0.0, 1.0, size) * std_rad / math.sqrt(2)
    pans = np.arctan(lateral_m / distances[:, None]) + noise
    estimates = estimated_distances(pans, lateral_m, std_rad)
    result = distance_error_by_range(estimates, distances)
    result["median"] = float(np.median(100.0 * np.abs(estimates - distances) / distances))
    return result


def paper_floors(samples: int = 200, seed: int = 0, mae_scale: float = 1.0) -> list[dict]:
    """One row per (set-up, before/after, noise shape): the floor and the paper's numbers.
    ``mae_scale`` multiplies every published MAE (to test how the floor scales)."""
    rng = np.random.default_rng(seed)
    floors = {}  # drawn in a fixed order, so that one seed gives one set of numbers
    for (column, when), given in EYE_MAE_DEG.items():
        mae = mae_scale * mae_per_position(given, LATERAL_LIST_CM[column])
        for shape in NOISE_SHAPES:
            floors[column, when, shape] = floor(mae, LATERAL_LIST_CM[column], shape, samples, rng)
    rows = []
    for setup, column in EYE_COLUMN_OF_SETUP.items():
        for when in ("before", "after"):
            for shape in NOISE_SHAPES:
                computed = floors[column, when, shape]
                published = PAPER_DISTANCE_ERROR[when][setup]
                rows.append(
                    {
                        "setup": setup,
                        "when": when,
                        "noise": shape,
                        "floor": {r: computed[r] for r in RANGES},
                        "floor_median": computed["median"],
                        "paper": {r: published[r] for r in RANGES},
                        "paper_over_floor": published["total"] / computed["total"],
                    }
                )
    return rows


def markdown(rows: list[dict]) -> str:
    head = (
        "| set-up | table | noise | floor 3-4.9 | floor 5-6.9 | floor 7-10 | floor total | "
        "floor median | paper 3-4.9 | paper 5-6.9 | paper 7-10 | paper total | paper/floor |"
    )
    lines = [head, "|---|---|---|" + "---:|" * 10]
    for row in rows:
        table = "4 (before)" if row["when"] == "before" else "5 (after)"
        numbers = [row["floor"][r] for r in RANGES] + [row["floor_median"]]
        numbers += [row["paper"][r] for r in RANGES]
        cells = " | ".join(f"{n:.2f} %" for n in numbers)
        lines.append(
            f"| {row['setup']} | {table} | {row['noise']} | {cells} | "
            f"{row['paper_over_floor']:.2f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.paper_floor", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--samples", type=int, default=200, help="noisy trials per distance")
    parser.add_argument("--seed", type=int, default=0, help="seed of numpy's default_rng")
    parser.add_argument("--json", type=Path, help="also write the rows here")
    args = parser.parse_args(argv)
    if args.samples < 1:
        print(f"[paper_floor] --samples must be ≥ 1, got {args.samples}", file=sys.stderr)
        return 2
    if args.json is not None and (why := file_problem(args.json)):
        print(f"[paper_floor] cannot write --json {args.json}: {why}", file=sys.stderr)
        return 2
    rows = paper_floors(args.samples, args.seed)
    if args.json is not None:  # first, so that a failed write leaves nothing printed
        result = {"samples": args.samples, "seed": args.seed, "rows": rows}
        try:
            args.json.write_text(json.dumps(result, indent=1) + "\n")
        except OSError as exc:
            print(f"[paper_floor] cannot write --json {args.json}: {exc}", file=sys.stderr)
            return 2
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
