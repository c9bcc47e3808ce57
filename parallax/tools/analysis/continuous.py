"""Distance from a continuous sweep's pursuit, and when to stop moving (beyond the paper: its
§4.1 pick-and-place made continuous; its first future work, §7, "decide when to stop moving
laterally").

For evaluations (parallax-eval) of runs with ``env.motion=continuous``, on the held-out
photographs, it prints the eye's error and two tables:

- **The eye's error, and the part a distance learner cannot undo**: the mean |q_p − α*_p|, and
  what is left of it once a smooth function of the distance (a cubic in d, position by position)
  is taken away: a repeatable error the network learns, an unrepeatable one it cannot.
- **What to read from the pursuit.** The distance error of a fresh distance learner of the run's
  settings, fitted by 5-fold cross-validation to the evaluation's own eye movements, fed either
  s, the pans as the body passes l_1 … l_r (what training uses), or one number, the pursuit gain
  g = Σ l_p·tan q_p / Σ l_p² (the slope of tan α against the body offset, ≈ 1/d for a perfect
  pursuit): does the eye's trajectory carry more than its slope?
- **When to stop moving.** In a sweep the pans at the first offsets do not depend on whether the
  body goes on, so stopping after l_p is the sweep cut short there. The movement planner
  (:class:`parallax.distance.planner.MovementPlanner`, its queue the run's last c training
  sweeps) estimates the distance from the pans passed so far; the fixed curve stops every
  presentation at l_p; the planned rows stop where the expected error plus the price of the
  travel (``movement.price_per_cm`` percentage points per cm, out and back) is least for the
  estimate so far, price by price. Each row: the mean lateral travel and the distance error.

    python -m parallax.tools.analysis.continuous EVAL_DIR… [--prices 0 0.01 …] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from parallax.config import load_run_config
from parallax.distance.metrics import distance_error_by_range
from parallax.distance.planner import MovementPlanner
from parallax.tools.analysis.eye_bound import network_cross_validated, perfect_pans
from parallax.tools.console import footer, header, progress
from parallax.tools.report.runs import EVAL_NAME, METRICS_NAME, eval_run_dir, read_record
from parallax.writable import file_problem

#: Prices of travel (percentage points of expected distance error per cm) for the planned rows.
PRICES = (0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)


def pursuit_gain(pans_deg: np.ndarray, lateral_m: np.ndarray) -> np.ndarray:
    """g = Σ l_p·tan q_p / Σ l_p² per presentation (rows of ``pans_deg``), in 1/m."""
    return np.tan(np.radians(pans_deg)) @ lateral_m / float(lateral_m @ lateral_m)


def eye_error_parts(result: dict, lateral_m) -> dict[str, float]:
    """The eye's mean |q_p − α*_p| over an evaluation's grid presentations, and the part of it a
    distance learner cannot undo: what is left after a cubic in d, fitted position by position,
    takes away each position's error as a smooth function of the distance."""
    distances = np.asarray(result["greedy_samples"]["grid"]["distances"], float)
    pans = np.asarray(result["greedy_samples_by_readout"][result["readout"]]["grid"]["pans"], float)
    errors = pans - perfect_pans(tuple(float(l) for l in lateral_m), tuple(distances))
    left = [e - np.polyval(np.polyfit(distances, e, 3), distances) for e in errors.T]
    return {
        "eye_mae_deg": float(np.abs(errors).mean()),
        "eye_unlearnable_deg": float(np.abs(left).mean()),
    }


def training_sweeps(run_dir: Path, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The run's last ``count`` training vectors s (every robot's) and their distances."""
    pans, distances = [], []
    for line in read_record(run_dir / METRICS_NAME).splitlines():
        record = json.loads(line)
        pans += record["pans"]
        distances += record["distances"]
    return np.asarray(pans[-count:], float), np.asarray(distances[-count:], float)


def fixed_stop(planner: MovementPlanner, pans: np.ndarray, last: int) -> tuple:
    """Every presentation stops after l_``last``: where, and the planner's estimates there."""
    seen = list(range(last + 1))
    stops = np.full(len(pans), last)
    return stops, np.array([planner.estimate(seen, s[: last + 1]) for s in pans])


def planned_stop(planner: MovementPlanner, pans: np.ndarray, price_per_cm: float) -> tuple:
    """Each presentation goes on past l_p while some longer sweep has a lower expected error
    plus price of travel, for the estimate from the pans passed so far: where it stops (indices
    into L) and its estimate there."""
    planner.price_per_cm = float(price_per_cm)
    r = pans.shape[1]
    stops, estimates = [], []
    for s in pans:
        stop = 0
        while stop < r - 1:
            seen = list(range(stop + 1))
            near = planner.estimate(seen, s[: stop + 1])
            costs = [planner.cost(list(range(q + 1)), seen, near) for q in range(stop, r)]
            if int(np.argmin(costs)) == 0:
                break
            stop += 1
        stops.append(stop)
        estimates.append(planner.estimate(list(range(stop + 1)), s[: stop + 1]))
    return np.asarray(stops), np.asarray(estimates)


def _inputs(eval_dir: Path):
    """The evaluation in ``eval_dir``, its run's folder and configuration; ValueError or
    FileNotFoundError for one that cannot be analysed."""
    result = json.loads(read_record(eval_dir / EVAL_NAME))
    run_dir = eval_run_dir(eval_dir, result.get("run_dir", ""))
    cfg = load_run_config(run_dir)
    if cfg.env.motion != "continuous":
        raise ValueError(f"{eval_dir}: its run did not sweep (env.motion={cfg.env.motion})")
    return result, run_dir, cfg


def analyse(eval_dir: Path, prices=PRICES) -> dict:
    eval_dir = Path(eval_dir)
    result, run_dir, cfg = _inputs(eval_dir)
    distances = np.asarray(result["greedy_samples"]["grid"]["distances"], float)
    pans = np.asarray(result["greedy_samples_by_readout"]["last"]["grid"]["pans"], float)
    lateral = np.asarray([float(l) for l in cfg.curriculum.lateral_positions])

    def error(estimates) -> dict:
        return distance_error_by_range(np.asarray(estimates), distances)

    rules = [(f"fixed: to {100 * l:g} cm", fixed_stop, p) for p, l in enumerate(lateral)]
    rules += [(f"planned: {price:g} per cm", planned_stop, price) for price in prices]
    # the two cross-validated networks and each stopping rule: seconds to a minute apiece
    bar = progress(total=2 + len(rules), desc=eval_dir.name, unit="fit")

    one_number = cfg.copy()  # the gain as a one-position vector, unweighted
    one_number.curriculum.lateral_positions = [float(lateral[-1])]
    one_number.distance.weighting = False
    readouts = {"pans at the offsets of L": error(network_cross_validated(cfg, pans, distances))}
    bar.update()
    gain = pursuit_gain(pans, lateral)[:, None]
    readouts["pursuit gain"] = error(network_cross_validated(one_number, gain, distances))
    bar.update()
    queue = training_sweeps(run_dir, int(cfg.distance.queue_size))
    planner = MovementPlanner(list(lateral), queue_size=len(queue[1]), price_per_trial=0.0)
    for s, d in zip(*queue):
        planner.observe(s, float(d))
    rows = []
    for label, rule, setting in rules:
        stops, estimates = rule(planner, pans, setting)
        travel = 2 * 100 * lateral[stops]  # out and back, as the planner prices it
        rows.append({"rule": label, "travel_cm": float(travel.mean()), **error(estimates)})
        bar.update()
    bar.close()
    return {
        "eval": str(eval_dir),
        "eye": eye_error_parts(result, lateral),
        "readouts": readouts,
        "stopping": rows,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.continuous", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("evals", nargs="+", metavar="EVAL_DIR", help="folders with an eval.json")
    parser.add_argument("--prices", nargs="+", type=float, default=list(PRICES))
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = parser.parse_args(argv)
    if any(not math.isfinite(p) or p < 0 for p in args.prices):
        print(f"continuous: error: --prices {args.prices}: must be ≥ 0", file=sys.stderr)
        sys.exit(2)
    if args.json and (why := file_problem(args.json)):
        print(f"continuous: error: --json {args.json} {why}", file=sys.stderr)
        sys.exit(2)
    try:
        for folder in args.evals:  # before the header: bad input is one line
            _inputs(Path(folder))
    except (FileNotFoundError, ValueError, KeyError) as exc:
        print(f"continuous: error: {exc}", file=sys.stderr)
        sys.exit(2)
    header(
        "continuous",
        f"distance from the continuous sweeps of {len(args.evals)} evaluation"
        + "s" * (len(args.evals) != 1),
        prices=", ".join(f"{p:g}" for p in args.prices),
        output=Path(args.json).resolve() if args.json else "the tables, printed",
    )
    try:
        results = [analyse(Path(folder), args.prices) for folder in args.evals]
    except (FileNotFoundError, ValueError, KeyError) as exc:
        print(f"continuous: error: {exc}", file=sys.stderr)
        sys.exit(2)
    for result in results:
        eye = result["eye"]
        print(
            f"\n{result['eval']}\n\nthe eye's error {eye['eye_mae_deg']:.3f}°, of which no "
            f"function of the distance takes away {eye['eye_unlearnable_deg']:.3f}°"
        )
        print("\n| readout | 3-4.9 m | 5-6.9 m | 7-10 m | total |")
        print("|---|---|---|---|---|")
        for name, e in result["readouts"].items():
            print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in e.values()) + " |")
        print("\n| stop | lateral travel (cm) | 3-4.9 m | 5-6.9 m | 7-10 m | total |")
        print("|---|---|---|---|---|---|")
        for row in result["stopping"]:
            values = [row[k] for k in ("3-4.9", "5-6.9", "7-10", "total")]
            print(
                f"| {row['rule']} | {row['travel_cm']:.1f} | "
                + " | ".join(f"{v:.2f}" for v in values)
                + " |"
            )
    if args.json:
        try:
            Path(args.json).write_text(json.dumps(results, indent=1) + "\n")
        except OSError as exc:
            print(f"continuous: error: cannot write --json {args.json}: {exc}", file=sys.stderr)
            sys.exit(2)
        footer("continuous", [args.json])


if __name__ == "__main__":
    main()
