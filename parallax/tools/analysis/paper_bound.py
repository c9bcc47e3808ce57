"""What distance error the paper's own eye errors allow, under stated assumptions (Tables 2–5).

Tables 2–3 give the eye-movement MAE of eq. 16 (degrees, last 100 trials) and its variance per
lateral position of the multi-position runs, before and after the perturbations; Tables 4–5 give
their distance errors. Here the pans are drawn from the geometry, q_p = atan(l_p/d), plus an
error of a stated kind whose mean absolute value is the table's MAE at p (unlisted positions
interpolated linearly), at every distance of the paper's grid 3.0, 3.1, …, 10.0 m, and the
distance is estimated from them by one of two estimators that know the geometry and the noise:

- ``least_squares``: the weighted least-squares nearness 1/d̂ = Σ w_p l_p q_p / Σ w_p l_p²,
  w_p = 1/σ_p²;
- ``grid_posterior``: the posterior over the 71 grid distances under the true noise model, and
  the d̂ that minimises its expected |d̂ − d|/d (a weighted median). Under the model's
  assumptions no estimator, a network included, does better on average.

The error models, each an assumption the bound rests on:

- ``gaussian`` / ``laplace``: zero-mean, independent from trial to trial and position to position;
- ``heavy_tails``: zero-mean and independent, Student-t with the degrees of freedom that give the
  table's variance: if the table's "variance" is that of the absolute error, E e² = var + MAE²,
  and var/MAE² of 2.1–2.5 (5–10 cm) is more than a Gaussian's 0.57 and a Laplace's 1.0. For the
  same MAE most trials are then closer to α*, and the posterior gains from it;
- ``half_bias``: half of each position's MAE is a repeatable undershoot (a bias the records show,
  and which a learner can subtract), the rest Gaussian noise scaled so that the error's mean
  absolute value stays the MAE.

The result is a bound under these assumptions, not a floor. It says what an eye with independent,
zero-mean errors of the tables' size allows; a distance error below it means the errors were not
of that kind (repeatable for a photograph and distance, biased, or heavier-tailed than any model
here), or that the distance figures come from an eye better than its tables report. It does not
rule out the paper's numbers.

    python -m parallax.tools.analysis.paper_bound [--samples N] [--seed S] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy import optimize, special, stats
from tqdm import tqdm

from parallax.distance.metrics import distance_error_by_range
from parallax.tools.analysis.synthetic_pans import PAPER_DISTANCES_M
from parallax.tools.report import paper_results as paper
from parallax.writable import file_problem

RANGES = ("3-4.9", "5-6.9", "7-10", "total")
ERROR_MODELS = ("gaussian", "laplace", "heavy_tails", "half_bias")
ESTIMATORS = ("least_squares", "grid_posterior")
#: The undershoot's share of the MAE in the ``half_bias`` model.
BIAS_SHARE = 0.5

#: (MAE, variance) in degrees per given lateral position (cm) of the two multi-position runs:
#: paper Table 2 ("before", §4.2.2) and Table 3 ("after" the perturbations, §5), from
#: parallax.tools.report.paper_results, the project's one copy of the paper's tables.
EYE_ERROR_DEG: dict[tuple[str, str], dict[int, tuple[float, float]]] = {
    (column, when): {int(cm): cell for cm, cell in table[column].items() if cell is not None}
    for when, table in (("before", paper.TABLE2), ("after", paper.TABLE3))
    for column in (paper.MULTI_5_10, paper.MULTI_5_20)
}

#: The run's lateral list L (cm) of each multi-position column (§4.2.1).
LATERAL_LIST_CM: dict[str, list[int]] = {
    column: [int(cm) for cm in cms] for column, cms in paper.MULTI_LISTS_CM.items()
}

#: Distance error (%) per range: paper Table 4 ("before") and Table 5 ("after"), and the eye
#: column (Tables 2–3) each set-up's pans come from (one 5-20 cm column for both 5-20 cm rows).
PAPER_DISTANCE_ERROR: dict[str, dict[str, dict[str, float]]] = {
    "before": paper.TABLE4,
    "after": paper.TABLE5,
}
EYE_COLUMN_OF_SETUP: dict[str, str] = {
    paper.NO_WEIGHTING_5_10: paper.MULTI_5_10,
    paper.NO_WEIGHTING_5_20: paper.MULTI_5_20,
    paper.WEIGHTING_5_20: paper.MULTI_5_20,
}


def per_position(given: dict[int, float], lateral_cm: list[int]) -> np.ndarray:
    """A given per-position figure at every position of L, linear between the given ones."""
    positions = sorted(given)
    return np.interp(lateral_cm, positions, [given[cm] for cm in positions])


def t_mean_abs(nu: float) -> float:
    """E|T| of a standard Student-t with ``nu`` > 1 degrees of freedom."""
    return (
        2
        * math.sqrt(nu)
        * math.exp(special.gammaln((nu + 1) / 2) - special.gammaln(nu / 2))
        / (math.sqrt(math.pi) * (nu - 1))
    )


def t_degrees_for(second_over_mae2: float) -> float:
    """ν of the Student-t whose E e²/E|e|² is the given ratio (> π/2, a Gaussian's; capped at
    200 for a ratio at or below it, where the t is a Gaussian in all but name)."""

    def ratio(nu: float) -> float:
        return nu / (nu - 2) / t_mean_abs(nu) ** 2

    if second_over_mae2 <= ratio(200.0):
        return 200.0
    return float(optimize.brentq(lambda nu: ratio(nu) - second_over_mae2, 2.0 + 1e-6, 200.0))


def biased_noise_sd(mae: float, bias: float) -> float:
    """σ of N(0, σ²) such that E|N − bias| = mae (bias < mae)."""

    def mean_abs(sigma: float) -> float:
        z = bias / sigma
        return sigma * math.sqrt(2 / math.pi) * math.exp(-z * z / 2) + bias * (
            1 - 2 * stats.norm.cdf(-z)
        )

    return float(optimize.brentq(lambda s: mean_abs(s) - mae, 1e-9, 10 * mae + 1e-9))


class ErrorModel:
    """The eye's error at each position of L: draws (degrees, bias removed) and log-densities."""

    def __init__(self, kind: str, mae_deg: np.ndarray, var_deg2: np.ndarray) -> None:
        self.kind = kind
        self.nu = None
        if kind == "gaussian":
            self.scale = mae_deg * math.sqrt(math.pi / 2)
        elif kind == "laplace":
            self.scale = mae_deg  # b = MAE
        elif kind == "heavy_tails":
            # one ν for the column, from the mean ratio of E e² = var + MAE² to MAE²
            seen = mae_deg > 0
            ratio = (var_deg2[seen] + mae_deg[seen] ** 2) / mae_deg[seen] ** 2
            self.nu = t_degrees_for(float(ratio.mean())) if seen.any() else 200.0
            self.scale = mae_deg / t_mean_abs(self.nu)
        elif kind == "half_bias":
            self.scale = np.array(
                [biased_noise_sd(m, BIAS_SHARE * m) if m > 0 else 0.0 for m in mae_deg]
            )
        else:
            raise ValueError(f"error model must be one of {ERROR_MODELS}, got {kind!r}")

    @property
    def least_squares_sd(self) -> np.ndarray:
        """Each position's noise standard deviation, for the least-squares weights."""
        if self.kind == "laplace":
            return self.scale * math.sqrt(2)
        if self.kind == "heavy_tails":
            return self.scale * math.sqrt(self.nu / (self.nu - 2))
        return self.scale

    def draw(self, size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        if self.kind == "laplace":
            return rng.laplace(0.0, 1.0, size) * self.scale
        if self.kind == "heavy_tails":
            return rng.standard_t(self.nu, size) * self.scale
        return rng.normal(0.0, 1.0, size) * self.scale  # gaussian, and half_bias less its bias

    def log_density(self, residual_deg: np.ndarray) -> np.ndarray:
        scale = np.maximum(self.scale, 1e-12)
        if self.kind == "laplace":
            return -np.abs(residual_deg) / scale
        if self.kind == "heavy_tails":
            return stats.t.logpdf(residual_deg / scale, self.nu)
        return -0.5 * (residual_deg / scale) ** 2


def least_squares(pans_deg: np.ndarray, lateral_m: np.ndarray, sd_deg: np.ndarray) -> np.ndarray:
    """Weighted least-squares nearness from q_p ≈ l_p·(1/d), inverted (weights 1/σ², guarded so
    that a noiseless eye gives equal weights)."""
    weights = 1.0 / np.maximum(sd_deg, 1e-12) ** 2
    pans = np.radians(pans_deg)
    nearness = (pans * weights * lateral_m).sum(axis=1) / (weights * lateral_m**2).sum()
    return 1.0 / np.maximum(nearness, 1e-3)  # a pan pointing away would give d < 0


def grid_posterior(
    pans_deg: np.ndarray, lateral_m: np.ndarray, model: ErrorModel, grid_m: np.ndarray
) -> np.ndarray:
    """The d of the grid minimising the posterior's expected |d̂ − d|/d (uniform prior)."""
    expected = np.degrees(np.arctan(lateral_m[None, :] / grid_m[:, None]))  # (grid, positions)
    log_post = model.log_density(pans_deg[:, None, :] - expected[None]).sum(axis=2)
    post = np.exp(log_post - log_post.max(axis=1, keepdims=True))
    weights = post / grid_m[None, :]  # expected relative error: a median weighted by p(d)/d
    cumulative = np.cumsum(weights, axis=1)
    index = (cumulative >= 0.5 * cumulative[:, -1:]).argmax(axis=1)
    return grid_m[index]


def bound(
    model: ErrorModel, lateral_cm: list[int], estimator: str, samples: int, rng
) -> dict[str, float]:
    """Mean error (%) per range and in total, and the median, of ``estimator`` on noisy pans."""
    lateral_m = np.asarray(lateral_cm, float) / 100.0
    distances = np.repeat(PAPER_DISTANCES_M, samples)
    truth = np.degrees(np.arctan(lateral_m[None, :] / distances[:, None]))
    pans = truth + model.draw(truth.shape, rng)
    if estimator == "least_squares":
        estimates = least_squares(pans, lateral_m, model.least_squares_sd)
    else:
        estimates = grid_posterior(pans, lateral_m, model, np.asarray(PAPER_DISTANCES_M))
    result = distance_error_by_range(estimates, distances)
    result["median"] = float(np.median(100.0 * np.abs(estimates - distances) / distances))
    return result


def paper_bounds(
    samples: int = 200, seed: int = 0, mae_scale: float = 1.0, progress: bool = False
) -> list[dict]:
    """One row per (set-up, before/after, error model, estimator): the bound and the paper's
    numbers. ``mae_scale`` multiplies every published MAE (to test how the bound scales)."""
    rng = np.random.default_rng(seed)
    computed = {}  # drawn in a fixed order, so that one seed gives one set of numbers
    cases = [
        (column, when, kind, estimator)
        for (column, when) in EYE_ERROR_DEG
        for kind in ERROR_MODELS
        for estimator in ESTIMATORS
    ]
    for column, when, kind, estimator in tqdm(cases, desc="bounds", disable=not progress):
        given = EYE_ERROR_DEG[column, when]
        lateral = LATERAL_LIST_CM[column]
        mae = mae_scale * per_position({cm: v[0] for cm, v in given.items()}, lateral)
        var = mae_scale**2 * per_position({cm: v[1] for cm, v in given.items()}, lateral)
        model = ErrorModel(kind, mae, var)
        computed[column, when, kind, estimator] = (
            bound(model, lateral, estimator, samples, rng),
            model.nu,
        )
    rows = []
    for setup, column in EYE_COLUMN_OF_SETUP.items():
        for when in ("before", "after"):
            for kind in ERROR_MODELS:
                for estimator in ESTIMATORS:
                    result, nu = computed[column, when, kind, estimator]
                    published = PAPER_DISTANCE_ERROR[when][setup]
                    rows.append(
                        {
                            "setup": setup,
                            "when": when,
                            "errors": kind,
                            "estimator": estimator,
                            "t_degrees_of_freedom": nu,
                            "bound": {r: result[r] for r in RANGES},
                            "bound_median": result["median"],
                            "paper": {r: published[r] for r in RANGES},
                            "paper_over_bound": (
                                published["total"] / result["total"] if result["total"] else None
                            ),
                        }
                    )
    return rows


def markdown(rows: list[dict]) -> str:
    """The totals: one row per set-up and table, one column per (error model, estimator)."""
    columns = [(kind, estimator) for kind in ERROR_MODELS for estimator in ESTIMATORS]
    short = {"least_squares": "LS", "grid_posterior": "posterior"}
    head = "| set-up | table | paper | " + " | ".join(
        f"{kind} {short[est]}" for kind, est in columns
    )
    lines = [head + " |", "|---|---|---:|" + "---:|" * len(columns)]
    by_case = {(r["setup"], r["when"], r["errors"], r["estimator"]): r for r in rows}
    for setup in EYE_COLUMN_OF_SETUP:
        for when in ("before", "after"):
            table = "4 (before)" if when == "before" else "5 (after)"
            paper_total = by_case[setup, when, columns[0][0], columns[0][1]]["paper"]["total"]
            cells = [f"{by_case[setup, when, k, e]['bound']['total']:.2f} %" for k, e in columns]
            lines.append(f"| {setup} | {table} | {paper_total:.2f} % | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.paper_bound", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--samples", type=int, default=200, help="noisy trials per distance")
    parser.add_argument("--seed", type=int, default=0, help="seed of numpy's default_rng")
    parser.add_argument("--json", type=Path, help="also write the rows here")
    args = parser.parse_args(argv)
    if args.samples < 1:
        print(f"[paper_bound] --samples must be ≥ 1, got {args.samples}", file=sys.stderr)
        return 2
    if args.json is not None and not args.json.absolute().parent.is_dir():
        print(f"[paper_bound] cannot write --json {args.json}: no such folder", file=sys.stderr)
        return 2
    if args.json is not None and (why := file_problem(args.json)):
        print(f"[paper_bound] cannot write --json {args.json}: {why}", file=sys.stderr)
        return 2
    print(
        f"[paper_bound] {len(ERROR_MODELS)} error models × {len(ESTIMATORS)} estimators on "
        f"Tables 2–3's eyes, {args.samples} trials per grid distance, seed {args.seed}",
        file=sys.stderr,
    )
    rows = paper_bounds(args.samples, args.seed, progress=True)
    if args.json is not None:  # first, so that a failed write leaves nothing printed
        result = {"samples": args.samples, "seed": args.seed, "rows": rows}
        try:
            args.json.write_text(json.dumps(result, indent=1) + "\n")
        except OSError as exc:
            print(f"[paper_bound] cannot write --json {args.json}: {exc}", file=sys.stderr)
            return 2
        print(f"[paper_bound] wrote {args.json}", file=sys.stderr)
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
