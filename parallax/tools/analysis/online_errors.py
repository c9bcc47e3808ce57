"""Where a run's online distance error jumps: the distance learner (paper §3.5, eqs. 9–15)
replayed on a finished run's logged eye movements, presentation by presentation.

The trainer reports the error of the last ``metrics.distance_window`` online predictions, each
made before its s is learnt. One wild prediction moves that figure for hundreds of
presentations. This tool replays the run's stream (as `parallax-replay` does, so the numbers are
the run's own for the same settings) under each combination of overrides and prints the worst
single predictions with the s they were made from, the fit's RMSE and μ just before, and the
windowed total error at a few presentations:

    python -m parallax.tools.analysis.online_errors RUN \\
        distance.lm.weight_decay=0,0.1 train.distance_readout=last,best_reward
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from parallax import readouts
from parallax.config import load_run_config
from parallax.distance.online import learn_online
from parallax.metrics import DistanceErrorTracker
from parallax.parts import distance_learner
from parallax.tools.console import footer, header, progress
from parallax.tools.replay import ReplayError, parse_sweep, read_stream
from parallax.tools.report.runs import METRICS_NAME, record_file


def trace(run_dir: str | Path, overrides: Sequence[str] = (), bar=None) -> list[dict]:
    """One row per online prediction: presentation, true and predicted distance (robot 0 of
    each presentation), its relative error (%), the windowed total error after it, and the RMSE
    (m) and μ of the fit that made it. ``bar``: a progress bar moved on by each presentation."""
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    cfg.merge_with_dotlist(list(overrides))
    learner = distance_learner(cfg)
    tracker = DistanceErrorTracker(window=int(cfg.metrics.distance_window))
    key = readouts.of_run(cfg).key
    rows, fit = [], {}
    for record in read_stream(run_dir):
        if bar is not None:
            bar.update()
        if not record["learnt_distance"]:
            continue
        pans = np.atleast_2d(np.asarray(record[key], dtype=np.float64))
        truth = float(record["distances"][0])
        predicted = float(learner.predict(pans[:1]).reshape(-1)[0]) if learner.is_ready else None
        stats = learn_online(learner, tracker, pans, record["distances"])
        if predicted is not None:
            rows.append(
                {
                    "presentation": int(record["presentation"]),
                    "distance_m": truth,
                    "predicted_m": predicted,
                    "error_pct": abs(predicted - truth) / truth * 100.0,
                    "window_total_pct": tracker.by_range()["total"],
                    "fit_rmse_m": fit.get("rmse_m"),
                    "fit_mu": fit.get("mu"),
                    "s_deg": [round(float(q), 3) for q in pans[0]],
                }
            )
        fit = stats or fit
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a finished parallax-train run directory")
    parser.add_argument("overrides", nargs="*", help="key=v1,v2 … (every combination is traced)")
    parser.add_argument("--worst", type=int, default=3, help="worst predictions to print")
    parser.add_argument("--out", help="write every row of every combination to this JSON file")
    args = parser.parse_args(argv)
    if record_file(Path(args.run) / METRICS_NAME) is None:
        print(f"online_errors: error: {args.run} has no metrics.jsonl", file=sys.stderr)
        sys.exit(2)
    torch.set_num_threads(1)
    results = {}
    try:
        combos = parse_sweep(args.overrides)  # distance settings only, as parallax-replay
    except ReplayError as exc:
        print(f"online_errors: error: {exc}", file=sys.stderr)
        sys.exit(2)
    try:  # before the header: a bad override is one line
        for combo in combos:
            load_run_config(Path(args.run)).merge_with_dotlist(list(combo))
        presentations = len(read_stream(Path(args.run)))
    except (ReplayError, ValueError, KeyError) as exc:
        print(f"online_errors: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        sys.exit(2)
    header(
        "online_errors",
        f"the distance learner replayed on {args.run}, presentation by presentation",
        settings=" | ".join(" ".join(c) or "(the run's settings)" for c in combos),
        output=Path(args.out).resolve() if args.out else "the worst predictions, printed",
    )
    bar = progress(total=presentations * len(combos), desc="presentations")
    for combo in combos:
        label = " ".join(combo) or "(the run's settings)"
        try:
            rows = trace(args.run, combo, bar)
        except (ReplayError, ValueError, KeyError) as exc:
            print(f"online_errors: error: {label}: {str(exc).splitlines()[0]}", file=sys.stderr)
            sys.exit(2)
        results[label] = rows
        if not rows:
            print(f"{label}: no online prediction (the queue never filled)")
            continue
        every = rows[:: len(rows) // 4 or 1] + rows[-1:]
        marks = sorted({r["presentation"] for r in every})
        window = {r["presentation"]: r["window_total_pct"] for r in rows}
        print(f"{label}: final windowed error {rows[-1]['window_total_pct']:.2f} %")
        print("  windowed total at " + ", ".join(f"{p}: {window[p]:.2f} %" for p in marks))
        for r in sorted(rows, key=lambda r: -r["error_pct"])[: args.worst]:
            rmse = "-" if r["fit_rmse_m"] is None else f"{r['fit_rmse_m']:.3f} m"
            mu = "-" if r["fit_mu"] is None else f"{r['fit_mu']:.0e}"
            print(
                f"  presentation {r['presentation']}: d {r['distance_m']:.1f} m, predicted "
                f"{r['predicted_m']:.2f} m ({r['error_pct']:.1f} %); fit before: RMSE {rmse}, "
                f"μ {mu}; s = {r['s_deg']}"
            )
    bar.close()
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=1))
        footer("online_errors", [args.out])


if __name__ == "__main__":
    main()
