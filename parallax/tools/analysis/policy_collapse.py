"""`python -m parallax.tools.analysis.policy_collapse RUN...`: when a run's natural actor-critic
(paper §3.4, Algorithm 3) turned deterministic, read from its logged `metrics.jsonl`.

Per run it prints the first presentation at which the actor's parameters |Θ| reached the
projection's ball (``policy.actor_projection_radius``; within ``--ball`` of it), the first at
which the policy's entropy fell below ``--entropy`` (ln 7 ≈ 1.95 is uniform over the seven pan
steps), the lowest recent eye-movement MAE (eq. 16, over metrics.summary_trials trials) within
the first ``--early`` presentations (once that window is full), and the recent MAE per lateral
position at the last presentation before §5's perturbation. A threshold never crossed is
"never".
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from parallax.config import load_run_config
from parallax.tools.report.runs import read_metrics

#: The thresholds' defaults: a fraction of the projection's radius, an entropy (nats), and the
#: presentations in which to look for the best early pursuit.
BALL, ENTROPY, EARLY = 0.99, 0.01, 300


def collapse(
    run_dir: str | Path, *, ball: float = BALL, entropy: float = ENTROPY, early: int = EARLY
) -> dict:
    """{"radius", "ball_at", "entropy_at", "early_best" (mae, presentation), "last" (min, max
    of the per-position recent MAE before the perturbation)}; None where a threshold was never
    crossed (or the run has no projection ball)."""
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    radius = cfg.policy.actor_projection_radius
    records = [r for r in read_metrics(run_dir) if not r.get("perturbed")]
    if not records:
        raise ValueError(f"{run_dir}: no presentations before the perturbation in metrics.jsonl")

    def first(crossed) -> int | None:
        return next((r["presentation"] for r in records if crossed(r)), None)

    ball_at = None
    if radius is not None:
        ball_at = first(lambda r: r["policy_actor_norm"] >= ball * radius)
    # the recent MAE is over the last summary_trials trials: full once that many were logged
    window = int(cfg.metrics.summary_trials)
    trials, early_records = 0, []
    for r in records:
        trials += len(r["pans"]) * len(r["pans"][0])
        if trials >= window and r["presentation"] <= early:
            early_records.append(r)
    if not early_records:
        raise ValueError(
            f"{run_dir}: fewer than {window} trials in the first {early} presentations"
        )
    best = min(early_records, key=lambda r: r["mae_recent"])
    last = list(records[-1]["mae_recent_per_position"].values())
    return {
        "radius": radius,
        "ball_at": ball_at,
        "entropy_at": first(lambda r: r["policy_entropy"] < entropy),
        "early_best": (best["mae_recent"], best["presentation"]),
        "last": (min(last), max(last)),
        "presentations": records[-1]["presentation"],
    }


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.policy_collapse", description=__doc__.split("\n")[0]
    )
    parser.add_argument("runs", nargs="+", help="run directories (with metrics.jsonl)")
    parser.add_argument("--ball", type=float, default=BALL, help="fraction of the radius")
    parser.add_argument("--entropy", type=float, default=ENTROPY, help="entropy threshold (nats)")
    parser.add_argument("--early", type=int, default=EARLY, help="presentations for the early MAE")
    args = parser.parse_args(argv)
    if not 0 < args.ball <= 1:
        parser.exit(2, f"{parser.prog}: error: --ball must be in (0, 1], got {args.ball}\n")
    rows = []
    for run in args.runs:
        try:
            rows.append(
                (run, collapse(run, ball=args.ball, entropy=args.entropy, early=args.early))
            )
        except (OSError, ValueError) as exc:
            parser.exit(2, f"{parser.prog}: error: {exc}\n")

    def at(value: int | None) -> str:
        return "never" if value is None else str(value)

    print(
        f"run | |Θ| ≥ {args.ball:g}·radius at | entropy < {args.entropy:g} at | "
        f"best recent MAE in the first {args.early} (at) | last recent MAE per position"
    )
    for run, c in rows:
        ball = "no ball" if c["radius"] is None else at(c["ball_at"])
        mae, when = c["early_best"]
        low, high = c["last"]
        print(
            f"{run} | {ball} | {at(c['entropy_at'])} | {mae:.2f}° ({when}) | "
            f"{low:.2f}–{high:.2f}° (presentation {c['presentations']})"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
