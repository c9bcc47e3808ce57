"""The soak: a long run of the recipe watched for numerical trouble (parallax/health.py).

    python -m parallax.tools.bench.soak                      # 10⁶ robot-iterations of the recipe
    python -m parallax.tools.bench.soak --iterations 200000 --out outputs/soak_short seed=1

Trains the recipe (the schema's defaults, plus any Hydra overrides) into ``--out`` as an
ordinary run directory, with ``train.stop_after_non_finite=null`` so that trouble is counted
rather than stopped at, for at least ``--iterations`` robot-iterations (robots × iterations per
robot), then reads its metrics.jsonl and reports:

- the non-finite values among the learners' logged numbers (the reward, the coder's errors, the
  policy's statistics, and the distance learner's once it fits: before its first fit its loss is
  NaN by definition);
- the updates the policy skipped as not finite, and the distance fits stopped on a non-finite
  Jacobian;
- the peak critic scale, mean |v·φ| over a presentation, and where it was reached, against the
  bound of ``train.critic_scale_warning``.

The report is printed and written to ``<out>/soak.json``. The run resumes like any other: an
interrupted soak continues where its last checkpoint left it when started again.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

#: The logged numbers a healthy run keeps finite (prefixes of metrics.jsonl keys).
WATCHED_PREFIXES = ("reward", "e_", "policy_")


def _non_finite(record: dict) -> list[str]:
    """The keys of ``record``'s watched numbers that are not finite."""
    keys = [k for k in record if k.startswith(WATCHED_PREFIXES)]
    if record.get("lm_trained") == 1:
        keys += [k for k in record if k.startswith("lm_")]
    return [
        k
        for k in keys
        if isinstance(record[k], (int, float)) and not math.isfinite(float(record[k]))
    ]


def soak_figures(records: list[dict], robots: int, skipped_updates: int, bound: float) -> dict:
    """The soak's report from a run's metrics.jsonl records (module docstring)."""
    non_finite: dict[str, int] = {}
    for record in records:
        for key in _non_finite(record):
            non_finite[key] = non_finite.get(key, 0) + 1
    scales = [
        (float(r["policy_critic_scale"]), int(r["presentation"]))
        for r in records
        if isinstance(r.get("policy_critic_scale"), (int, float))
        and math.isfinite(float(r["policy_critic_scale"]))
    ]
    peak, at = max(scales) if scales else (None, None)
    return {
        "presentations": len(records),
        "robot_iterations": int(records[-1]["steps"]) * robots if records else 0,
        "non_finite_values": sum(non_finite.values()),
        "non_finite_by_key": non_finite,
        "presentations_with_non_finite": sum(1 for r in records if _non_finite(r)),
        "skipped_policy_updates": skipped_updates,
        "distance_fits_stopped_non_finite": sum(
            1 for r in records if r.get("lm_trained") == 1 and r.get("lm_stopped_non_finite")
        ),
        "peak_critic_scale": peak,
        "peak_critic_scale_presentation": at,
        "critic_scale_bound": bound,
        "presentations_above_bound": sum(1 for s, _ in scales if s > bound),
    }


def format_figures(figures: dict) -> str:
    peak = figures["peak_critic_scale"]
    return "\n".join(
        [
            f"soak: {figures['robot_iterations']} robot-iterations in "
            f"{figures['presentations']} presentations ({figures['wall_time_s']:.0f} s)",
            f"non-finite values: {figures['non_finite_values']} "
            f"(in {figures['presentations_with_non_finite']} presentations)",
            f"updates skipped as not finite: {figures['skipped_policy_updates']} of the policy's, "
            f"{figures['distance_fits_stopped_non_finite']} distance fits",
            "peak critic scale mean |v·φ|: "
            + (
                "—"
                if peak is None
                else f"{peak:.4g} at presentation {figures['peak_critic_scale_presentation']} "
                f"(bound {figures['critic_scale_bound']:g}; "
                f"{figures['presentations_above_bound']} presentations above it)"
            ),
        ]
    )


def _fail(message: str) -> None:
    print(f"soak: error: {message}", file=sys.stderr)
    sys.exit(2)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.bench.soak", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument(
        "--iterations",
        type=int,
        default=1_000_000,
        help="robot-iterations to run at least (default 10⁶)",
    )
    parser.add_argument(
        "--out", default="outputs/soak", help="the run directory (default %(default)s)"
    )
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the recipe, e.g. seed=1")
    args = parser.parse_args(argv)
    if args.iterations < 1:
        _fail(f"--iterations must be ≥ 1, got {args.iterations}")
    from parallax.config import compose
    from parallax.config.overrides import composition_error
    from parallax.writable import folder_problem

    overrides = [*args.overrides, "train.stop_after_non_finite=null"]
    error = composition_error(overrides, check=True)
    if error:
        _fail(error)
    problem = folder_problem(args.out)
    if problem:
        _fail(f"--out {args.out}: {problem}; choose another folder")
    from parallax.run_folder import RunLock, RunLocked

    cfg = compose(overrides)
    out = Path(args.out)
    # the run folder has one writer (parallax.run_folder), this soak, from its first write on
    lock = RunLock(out, program="python -m parallax.tools.bench.soak")
    try:
        lock.acquire()
    except RunLocked as exc:
        _fail(f"{exc}; wait for it to end, or choose another folder with --out")
    try:
        return soak(args, cfg, out)
    finally:
        lock.release()


def soak(args: argparse.Namespace, cfg, out: Path) -> dict:
    """Train ``cfg`` into ``out`` for at least ``args.iterations`` robot-iterations; the report."""
    from parallax.trainer import Trainer

    robots = int(cfg.env.robots)
    # iterations per robot and presentation on the final lateral list (earlier stages of a
    # staged curriculum have fewer: the loop below tops the run up)
    per_presentation = len(cfg.curriculum.lateral_positions) * int(cfg.env.trial_length) * robots
    presentations = math.ceil(args.iterations / per_presentation)
    skipped, done = 0, 0
    while done < args.iterations:
        cfg.train.presentations = presentations
        trainer = Trainer(cfg, out)
        try:
            summary = trainer.fit()
            skipped = trainer.skipped_updates()
        finally:
            trainer.exp.close()
        done = int(summary["steps"]) * robots
        presentations += math.ceil((args.iterations - done) / per_presentation)
    records = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    figures = soak_figures(records, robots, skipped, float(cfg.train.critic_scale_warning))
    figures.update(
        overrides=list(args.overrides),
        wall_time_s=float(summary["timing"]["wall_time_s"]),  # over every resumed part
        run_dir=str(out),
    )
    (out / "soak.json").write_text(json.dumps(figures, indent=2) + "\n")
    print(format_figures(figures), flush=True)
    return figures


if __name__ == "__main__":
    main()
