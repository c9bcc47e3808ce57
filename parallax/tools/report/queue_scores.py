"""`python -m parallax.tools.report.queue_scores RUN_OR_MULTIRUN_DIR…`: the paper's probable
scoring of Tables 4–5 (§6: the network on its own queue S at the end of each phase) added to the
records of finished runs that predate it.

The trainer writes that score into summary.json (``distance_error_queue``, and the same under
``before_perturbation``). For a run whose summary lacks it, the distance learner is replayed as
trained (:func:`parallax.tools.replay.replay` without overrides, on the run's own logged vectors
s: the learner never acts on the world, so this is the run's own learner); the replay's online
errors must agree with the run's own to RELATIVE_TOLERANCE, and only then is the score added to
the run's summary.json, with ``distance_error_queue_from`` saying how it was made. Every run is
replayed and checked before any summary is written: a run that fails (a replay's record, errors
that disagree) is named, the exit code is 2, and nothing is changed. Runs that already hold the
score, and runs without a summary.json (still training, or stopped as diverged), are left alone.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from parallax.metrics import finite_or_none
from parallax.run_folder import RunLock, RunLocked, probe_all, write_atomic
from parallax.tools.report.runs import SUMMARY_NAME, ReportError, find_run_dirs

#: How far (relative) the replay's online errors may be from the run's own: the logged vectors s
#: are the run's exactly, so only the order of a few sums may differ.
RELATIVE_TOLERANCE = 1e-9
#: What ``distance_error_queue_from`` says in a summary this tool completed.
MADE_BY = "parallax-replay as trained (python -m parallax.tools.report.queue_scores)"
QUEUE_KEY = "distance_error_queue"


def _agree(replayed: dict, logged: dict, where: str) -> None:
    """A ValueError naming the first range where the replay's online error is not the run's."""
    replayed = finite_or_none(replayed or {})
    for key in sorted(set(replayed) | set(logged or {})):
        a, b = replayed.get(key), (logged or {}).get(key)
        same = a is None and b is None
        if a is not None and b is not None:
            same = math.isclose(a, b, rel_tol=RELATIVE_TOLERANCE, abs_tol=1e-12)
        if not same:
            raise ValueError(
                f"{where}: the replayed online error at {key} is {a}, the run's {b}; "
                "the replay is not this run's learner"
            )


def completed_summary(run: Path) -> dict | None:
    """The run's summary with the queue scores its phases lack, from a replay as trained that
    reproduces its online errors; None when it holds them already."""
    from parallax.tools.replay import ReplayError, replay

    summary_path = run / SUMMARY_NAME
    if not summary_path.is_file():
        raise ValueError(f"{run}: no {SUMMARY_NAME} (only finished runs are scored)")
    summary = json.loads(summary_path.read_text(encoding="utf-8"))
    if summary.get("replayed_from"):
        raise ValueError(f"{run}: a replay's record; parallax-replay its source again instead")
    before = summary.get("before_perturbation")
    if QUEUE_KEY in summary and (before is None or QUEUE_KEY in before):
        return None
    try:
        replayed = replay(run, rescore=[])["summary"]
    except ReplayError as error:
        raise ValueError(str(error)) from None
    _agree(replayed["distance_error"], summary.get("distance_error"), f"{run}")
    summary[QUEUE_KEY] = finite_or_none(replayed[QUEUE_KEY])
    if before is not None:
        replayed_before = replayed["before_perturbation"]
        _agree(replayed_before["distance_error"], before.get("distance_error"), f"{run}, before")
        before[QUEUE_KEY] = finite_or_none(replayed_before[QUEUE_KEY])
    summary[f"{QUEUE_KEY}_from"] = MADE_BY
    return summary


def add_queue_scores(paths: Sequence[str | Path]) -> list[Path]:
    """Completes the summaries of the finished runs at or below ``paths`` that lack the queue
    scores; returns the runs changed. Every run is checked before any is written."""
    found = [run for path in paths for run in find_run_dirs(path)]
    runs = [run for run in found if (run / SUMMARY_NAME).is_file()]
    held = probe_all(runs)
    if held is not None:
        raise held
    completed = {}
    for run in runs:
        summary = completed_summary(run)
        if summary is not None:
            completed[run] = summary
    for run, summary in completed.items():
        with RunLock(run, program="python -m parallax.tools.report.queue_scores"):
            text = json.dumps(summary, indent=2, allow_nan=False) + "\n"
            write_atomic(run / SUMMARY_NAME, text)
    return list(completed)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.queue_scores",
        description=__doc__.split("\n\n")[0],
    )
    parser.add_argument("paths", nargs="+", metavar="RUN_OR_MULTIRUN_DIR")
    args = parser.parse_args(argv)
    try:
        changed = add_queue_scores(args.paths)
    except RunLocked as error:
        print(f"[queue_scores] error: {error}; wait for it to end", file=sys.stderr)
        raise SystemExit(2) from None
    except (ReportError, ValueError) as error:
        print(f"[queue_scores] error: {error}", file=sys.stderr)
        raise SystemExit(2) from None
    for run in changed:
        print(f"[queue_scores] {run}: the network on its own queue added")
    print(f"[queue_scores] {len(changed)} summaries completed")


if __name__ == "__main__":
    main()
