"""`python -m parallax.tools.analysis.time_to_learn RUN...`: when a run's eye first met an MAE
target at every lateral position (its "time to learn"; the MAE is |q_p − α*| of eq. 16, over
the last ``trials`` trials of each position, as in Tables 2–3).

It reads `metrics.jsonl`: per-position recent MAEs where the trainer logged them
(``mae_recent_per_position``, over metrics.summary_trials trials), else recomputes them from
the logged pans with the world's α* for each (distance, lateral position). Only the part before
§5's perturbation counts. Wall time is the TensorBoard events' clock at that presentation, minus
the first event's, plus one presentation's mean duration (a resumed run's pause would count, so
use uninterrupted runs).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from parallax.config import load_run_config
from parallax.metrics import EyeMovementTracker, position_label
from parallax.tools.report.runs import METRICS_NAME, read_metrics, record_file


def _target_table(pairs: set[tuple[float, float]]) -> dict[tuple[float, float], float]:
    """α* (degrees) for each (distance m, lateral m), from the world's kinematics, unperturbed."""
    import parallax.envs

    env = parallax.envs.load(
        seed=0,
        lateral_positions=[0.05],
        trial_length=2,
        image_size=32,
        initial_pan_jitter_deg=0.0,
    )
    try:
        physics = env.physics
        table = {}
        for distance, lateral in sorted(pairs):
            physics.set_stimulus(0, distance)
            physics.set_lateral_position(lateral)
            table[(distance, lateral)] = physics.target_pan_deg()
        return table
    finally:
        env.close()


def trial_errors(run_dir: str | Path) -> dict:
    """Every robot's trials before the perturbation, from the logged pans and the world's α*:
    {"presentations", "steps" (one per row), "lateral_positions", "labels", "pans" and "targets"
    ((trials, r) arrays, B rows per presentation), "errors" = |pans − targets|}."""
    run_dir = Path(run_dir)
    records = [r for r in read_metrics(run_dir) if not r.get("perturbed")]
    lateral = [float(l) for l in load_run_config(run_dir).curriculum.lateral_positions]
    # a staged curriculum's earlier lists are not the final L: left out
    records = [r for r in records if np.asarray(r["pans"]).shape[1] == len(lateral)]
    table = _target_table({(float(d), l) for r in records for d in r["distances"] for l in lateral})
    pans, targets, presentations, steps = [], [], [], []
    for r in records:
        for row, distance in zip(r["pans"], r["distances"]):
            pans.append(row)
            targets.append([table[(float(distance), l)] for l in lateral])
            presentations.append(r["presentation"])
            steps.append(r["steps"])
    pans_arr = np.asarray(pans, dtype=np.float64).reshape(-1, len(lateral))
    targets_arr = np.asarray(targets, dtype=np.float64).reshape(-1, len(lateral))
    return {
        "presentations": presentations,
        "steps": steps,
        "lateral_positions": lateral,
        "labels": [position_label(l) for l in lateral],
        "pans": pans_arr,
        "targets": targets_arr,
        "errors": np.abs(pans_arr - targets_arr),
    }


def recent_mae_per_position(run_dir: str | Path, trials: int = 100) -> list[dict]:
    """Per unperturbed presentation: {presentation, steps, mae: {position: recent MAE}} — the
    trainer's own EyeMovementTracker.last_trials, logged or replayed on the recomputed trials."""
    run_dir = Path(run_dir)
    records = [r for r in read_metrics(run_dir) if not r.get("perturbed")]
    logged_window = int(load_run_config(run_dir).metrics.summary_trials)
    if trials == logged_window and records and all("mae_recent_per_position" in r for r in records):
        return [
            {
                "presentation": r["presentation"],
                "steps": r["steps"],
                "mae": r["mae_recent_per_position"],
            }
            for r in records
        ]
    table = trial_errors(run_dir)
    tracker = EyeMovementTracker(table["lateral_positions"], window=trials)
    out = []
    for i, (pans, targets) in enumerate(zip(table["pans"], table["targets"])):
        for label, pan, target in zip(table["labels"], pans, targets):
            tracker.record(label, pan, target)
        last_of_presentation = (
            i + 1 == len(table["pans"])
            or table["presentations"][i + 1] != table["presentations"][i]
        )
        if last_of_presentation:
            out.append(
                {
                    "presentation": table["presentations"][i],
                    "steps": table["steps"][i],
                    "mae": {k: v["mean"] for k, v in tracker.last_trials(trials).items()},
                }
            )
    return out


def _last_trials(run_dir: str | Path, trials: int) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(position labels, |error| and signed error of the last ``trials`` trials before the
    perturbation): signed + when the eye went past α*, − when it stopped short or turned the wrong
    way (seen from the start at 0)."""
    table = trial_errors(run_dir)
    past = (table["pans"] - table["targets"]) * np.sign(table["targets"])
    return list(table["labels"]), table["errors"][-trials:], past[-trials:]


def _spread(labels: list[str], tail: np.ndarray, past: np.ndarray, runaway_deg: float) -> dict:
    spread = {}
    for p, k in enumerate(labels):
        runaway = tail[:, p] > runaway_deg
        spread[k] = {
            "mean": float(tail[:, p].mean()),
            "median": float(np.median(tail[:, p])),
            "runaway_share": float(runaway.mean()),
            "trials": int(tail.shape[0]),
            "past_share": float((past[runaway, p] > 0).mean()) if runaway.any() else float("nan"),
            "runaway_signed_mean": float(past[runaway, p].mean())
            if runaway.any()
            else float("nan"),
        }
    return spread


def last_trials_spread(run_dir: str | Path, trials: int = 100, runaway_deg: float = 1.0) -> dict:
    """Per position, over the last ``trials`` trials before the perturbation: mean (Tables 2–3),
    median, the share of trials off by more than ``runaway_deg`` — a mean far above the median
    means a few runaway trials, not a uniformly imprecise eye — and which way the runaways went:
    ``past_share`` of them ended beyond the target (the pan past α*, seen from the start at 0),
    ``runaway_signed_mean`` their mean error in that sense (positive: past the target, negative:
    short of it or the wrong way)."""
    return _spread(*_last_trials(run_dir, trials), runaway_deg)


def pooled_spread(run_dirs, trials: int = 100, runaway_deg: float = 1.0) -> dict:
    """:func:`last_trials_spread` over the last ``trials`` trials of every run together (e.g. the
    seeds of one setting); the runs must share their lateral positions."""
    parts = [_last_trials(run, trials) for run in run_dirs]
    labels = parts[0][0]
    for run, (other, _, _) in zip(run_dirs, parts):
        if other != labels:
            raise ValueError(
                f"{run} has lateral positions {other}, not {labels}: pool runs of one setting"
            )
    return _spread(
        labels,
        np.concatenate([t for _, t, _ in parts]),
        np.concatenate([p for _, _, p in parts]),
        runaway_deg,
    )


def _wall_clock(run_dir: Path) -> dict[int, float]:
    """Seconds since the start of the run at each logged step, from TensorBoard's clock; empty
    (wall time unknown) when the run has no TensorBoard folder, e.g. one copied without it."""
    import logging

    if not (run_dir / "tb").is_dir():
        return {}

    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    # a resumed run's writer starts a new events file with a purge marker; TensorBoard warns
    # about it, but the scalars read here are complete
    logging.getLogger("tensorboard").setLevel(logging.ERROR)
    acc = EventAccumulator(str(run_dir / "tb"), size_guidance={"scalars": 0})
    acc.Reload()
    if "pursuit/mae_recent" not in acc.Tags().get("scalars", []):
        return {}
    events = acc.Scalars("pursuit/mae_recent")
    if len(events) < 2:
        return {}
    start = events[0].wall_time
    per_event = (events[-1].wall_time - start) / (len(events) - 1)
    return {e.step: e.wall_time - start + per_event for e in events}


def time_to_learn(run_dir: str | Path, threshold: float = 0.2, trials: int = 100) -> dict:
    """The first presentation whose recent MAE is ≤ threshold at every position (None if never),
    with its iterations and wall time; ``trials`` recent trials per position must exist."""
    run_dir = Path(run_dir)
    rows = recent_mae_per_position(run_dir, trials)
    robots = int(load_run_config(run_dir).env.robots)  # trials per position per presentation
    result = {
        "run_dir": str(run_dir),
        "threshold_deg": threshold,
        "trials": trials,
        "presentations_seen": len(rows),
        "presentation": None,
        "steps": None,
        "wall_time_s": None,
        "worst_position_at_end": None,
    }
    if rows:
        worst = max(rows[-1]["mae"].items(), key=lambda kv: kv[1])
        result["worst_position_at_end"] = {"position": worst[0], "mae_deg": worst[1]}
    row = first_learnt(rows, robots, trials, threshold)
    if row is not None:
        result["presentation"], result["steps"] = row["presentation"], row["steps"]
        result["wall_time_s"] = _wall_clock(run_dir).get(row["steps"])
    return result


def first_learnt(
    rows: list[dict], robots: int, trials: int, threshold: float, positions=None
) -> dict | None:
    """The first of :func:`recent_mae_per_position`'s rows with ``trials`` trials seen per
    position (``robots`` per presentation) whose recent MAE is ≤ threshold at every position
    of ``positions`` (all if None); None if there is none."""
    for i, row in enumerate(rows):
        mae = row["mae"] if positions is None else {p: row["mae"][p] for p in positions}
        if (i + 1) * robots >= trials and all(v <= threshold for v in mae.values()):
            return row
    return None


def learning_curve(run_dir: str | Path, trials: int = 100) -> dict:
    """The worst position's recent MAE after each presentation, against robot-iterations (steps ×
    robots: what B robots experienced together) and against wall time — how B = 1 and B = 16
    compare per environment step and per second."""
    run_dir = Path(run_dir)
    robots = int(load_run_config(run_dir).env.robots)
    rows = recent_mae_per_position(run_dir, trials)
    clock = _wall_clock(run_dir)
    return {
        "robots": robots,
        "robot_iterations": [r["steps"] * robots for r in rows],
        "wall_time_s": [clock.get(r["steps"], float("nan")) for r in rows],
        "worst_mae_deg": [max(r["mae"].values()) for r in rows],
    }


def plot_learning_curves(run_dirs, path: str | Path, trials: int = 100) -> Path:
    from parallax.tools import plots

    curves = {}
    for run_dir in run_dirs:
        cfg = load_run_config(run_dir)
        curves[f"B={int(cfg.env.robots)}, seed {int(cfg.seed)}"] = learning_curve(run_dir, trials)
    return plots.learning_curves_by_robots(curves, path, trials)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.time_to_learn", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("runs", nargs="+", help="run directories (with metrics.jsonl)")
    parser.add_argument("--threshold", type=float, default=0.2, help="MAE target, degrees")
    parser.add_argument("--trials", type=int, default=100, help="recent trials per position")
    parser.add_argument(
        "--spread",
        action="store_true",
        help="also print the last trials' mean, median and share off by > 1° per position",
    )
    parser.add_argument(
        "--pooled",
        action="store_true",
        help="also print the spread of all runs' last trials together (the seeds of one setting)",
    )
    parser.add_argument(
        "--curves",
        help="also plot the worst position's recent MAE against "
        "robot-iterations and wall time into this PNG (B = 1 against B = 16)",
    )
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args(argv)
    if args.threshold <= 0 or args.trials < 1:
        print(
            f"[time_to_learn] --threshold must be > 0 and --trials ≥ 1, got {args.threshold} "
            f"and {args.trials}",
            file=sys.stderr,
        )
        return 2
    missing = [r for r in args.runs if record_file(Path(r) / METRICS_NAME) is None]
    if missing:
        print(f"[time_to_learn] no metrics.jsonl in {missing[0]}", file=sys.stderr)
        return 2
    results = [time_to_learn(r, args.threshold, args.trials) for r in args.runs]
    for r in results:
        worst = r["worst_position_at_end"]
        worst_text = (
            f"worst at the end: {worst['position']} cm {worst['mae_deg']:.3f}°"
            if worst
            else "no data"
        )
        if r["presentation"] is None:
            print(
                f"{r['run_dir']}: not reached in {r['presentations_seen']} presentations "
                f"({worst_text})"
            )
        else:
            wall = (
                f"{r['wall_time_s'] / 60:.1f} min"
                if r["wall_time_s"] is not None
                else "wall time unknown"
            )
            print(
                f"{r['run_dir']}: ≤ {r['threshold_deg']}° at every position after presentation "
                f"{r['presentation']} ({r['steps']} iterations, {wall}; {worst_text})"
            )
        if args.spread:
            r["spread"] = last_trials_spread(r["run_dir"], args.trials)
            _print_spread(r["spread"])
    pooled = None
    if args.pooled:
        try:
            pooled = pooled_spread(args.runs, args.trials)
        except ValueError as error:
            print(f"[time_to_learn] --pooled: {error}", file=sys.stderr)
            return 2
        print(f"all {len(args.runs)} runs together:")
        _print_spread(pooled)
    if args.curves:
        print(f"curves: {plot_learning_curves(args.runs, args.curves, args.trials)}")
    if args.json:
        Path(args.json).write_text(
            json.dumps(results if pooled is None else {"runs": results, "pooled": pooled}, indent=1)
        )
    return 0


def _print_spread(spread: dict) -> None:
    print(
        "  last trials before the perturbation, per position: "
        + "  ".join(
            f"{k} cm {v['mean']:.2f}/{v['median']:.2f}°/{100 * v['runaway_share']:.0f}%"
            for k, v in spread.items()
        )
        + "   (mean/median/share > 1°)"
    )
    runaways = {k: v for k, v in spread.items() if v["runaway_share"] > 0}
    if runaways:
        print(
            "  runaways past the target / their mean signed error (+ past α*, − short or the wrong "
            "way): "
            + "  ".join(
                f"{k} cm {100 * v['past_share']:.0f}%/{v['runaway_signed_mean']:+.2f}°"
                for k, v in runaways.items()
            )
        )


if __name__ == "__main__":
    sys.exit(main())
