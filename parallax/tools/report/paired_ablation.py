"""`python -m parallax.tools.report.paired_ablation DIR... --factor KEY`: one ablation as paired
differences against its baseline, each with a 95 % interval and a verdict.

The runs (trained, or replayed by parallax-replay) below DIR differ in the setting KEY (e.g.
``coder.scales``, ``distance.y``, ``distance.queue_size``) and in their seed; each value of KEY
is compared with the baseline value (``--baseline``, default the first, its numbers ordered as
numbers) on the seeds both have, measure by measure, before and after §5's perturbation:

- ``eye``: the last 100 trials' mean eye error at each lateral position (Tables 2–3), paired
  position by position;
- ``held_out``: the frozen model on held-out photographs (parallax-eval; of several evaluations,
  the one with the most photographs per distance), paired photograph by photograph where the
  evaluations keep each trial's error, else distance by distance; where the two runs of a seed
  differ in how many photographs their fullest evaluation has, the pair is their own
  evaluations (one photograph per distance), so that both sides score the same trials;
- ``queue``: the network on its own queue at the end of the phase (the paper's probable scoring
  of Tables 4–5; queues of another size hold other vectors, so this pairs seed totals only);
- ``trained_eye``: the eye as trained on the grid, the learning policy on the training
  photographs (parallax-eval --split train; the paper's other probable scoring), seed totals;
- ``online``: the trainer's (or replay's) online error over its window, seed totals.

The difference is (value − baseline), so a negative one is an improvement; its interval is the
two-level bootstrap of parallax.tools.report.paired over seeds and samples, and the verdict says
whether the interval excludes zero. Where it does not, ``seeds that would tell`` estimates how
many seeds the observed mean difference would need.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from parallax.tools.report.groups import Stat
from parallax.tools.report.paired import paired_difference, seed_means, seeds_needed
from parallax.tools.report.runs import ReportError, Run, find_run_dirs, load_run
from parallax.writable import file_problem

PHASES = ("before", "after")


def _eye(run: Run, phase: str) -> list[float] | None:
    trials = run.last_trials(phase)
    if not trials:
        return None
    return [float(trials[label]["mean"]) for label in run.lateral_labels if label in trials]


def _held_out(run: Run, phase: str, most_photographs: bool = True) -> list[float] | None:
    found = run.eval_for(phase, most_photographs=most_photographs)
    distance = (found or {}).get("distance")
    if not distance:
        return None
    if distance.get("errors"):
        return [float(e) for e in distance["errors"]]
    return [float(v) for v in distance["per_distance"].values()]


def _total(by_range: dict | None) -> list[float] | None:
    total = (by_range or {}).get("total")
    return None if total is None or not math.isfinite(float(total)) else [float(total)]


MEASURES: dict[str, Callable[[Run, str], list[float] | None]] = {
    "eye": _eye,
    "held_out": _held_out,
    "queue": lambda run, phase: _total(run.queue_distance(phase)),
    "trained_eye": lambda run, phase: _total(run.trained_eye_distance(phase)),
    "online": lambda run, phase: _total(run.online_distance(phase)),
}
#: A measure's reading on fewer samples, for a seed whose two runs differ in the samples of the
#: first: both sides read again with it.
ALIKE: dict[str, Callable[[Run, str], list[float] | None]] = {
    "held_out": lambda run, phase: _held_out(run, phase, most_photographs=False),
}
UNITS = {"eye": "°", "held_out": " %", "queue": " %", "trained_eye": " %", "online": " %"}


def _value_text(value) -> str:
    return json.dumps(value) if not isinstance(value, str) else value


def factor_value(flat: dict, factor: str) -> str:
    """A run's value of ``factor``: one setting's value, or for several comma-separated keys
    (e.g. ``distance.weighting,distance.y``) ``key=value`` of each, joined by ", "."""
    keys = factor.split(",")
    missing = [key for key in keys if key not in flat]
    if missing:
        raise ReportError(f"no setting {missing[0]}")
    if len(keys) == 1:
        return _value_text(flat[factor])
    return ", ".join(f"{key}={_value_text(flat[key])}" for key in keys)


def runs_by_value(paths: Sequence[str | Path], factor: str) -> dict[str, dict[int, Run]]:
    """Finished runs below ``paths`` by their value of ``factor`` and their seed."""
    by_value: dict[str, dict[int, Run]] = {}
    for path in paths:
        for run_dir in find_run_dirs(path):
            run = load_run(run_dir)
            if run.summary is None:
                continue
            try:
                value = factor_value(run.flat, factor)
            except ReportError as exc:
                raise ReportError(f"{run_dir}: {exc}") from None
            seeds = by_value.setdefault(value, {})
            if int(run.seed) in seeds:
                raise ReportError(
                    f"{run_dir} and {seeds[int(run.seed)].path}: two runs of {factor}="
                    f"{value} with seed {run.seed}; give one set-up's runs"
                )
            seeds[int(run.seed)] = run
    if len(by_value) < 2:
        raise ReportError(f"{list(map(str, paths))}: fewer than two values of {factor}")
    return by_value


def natural_order(value: str) -> list:
    """A sort key that orders the numbers inside a value as numbers (c = 50, 100, 300, 1000)."""
    parts = re.split(r"(-?\d+(?:\.\d+)?)", value)
    return [(0, float(part), "") if k % 2 else (1, 0.0, part) for k, part in enumerate(parts)]


def _pairs(
    mine: dict[int, list[float]],
    base: dict[int, list[float]],
    measure: str,
    phase: str,
    mine_runs: dict[int, Run],
    base_runs: dict[int, Run],
) -> tuple[list[list[float]], list[list[float]]]:
    """The samples of the seeds both sides have, side by side, each seed's two on the same
    samples (read again with :data:`ALIKE` where their counts differ)."""
    a, b = [], []
    for seed in sorted(mine):
        if not base.get(seed):
            continue
        ours, theirs = mine[seed], base[seed]
        if len(ours) != len(theirs) and measure in ALIKE:
            ours = ALIKE[measure](mine_runs[seed], phase) or []
            theirs = ALIKE[measure](base_runs[seed], phase) or []
        if ours and len(ours) == len(theirs):
            a.append(ours)
            b.append(theirs)
    return a, b


def ablation(paths: Sequence[str | Path], factor: str, baseline: str | None = None) -> dict:
    """Every value of ``factor`` against the baseline, measure by measure and phase by phase."""
    by_value = runs_by_value(paths, factor)
    values = sorted(by_value, key=natural_order)
    baseline = baseline if baseline is not None else values[0]
    if baseline not in by_value:
        raise ReportError(f"--baseline {baseline}: the values of {factor} are {values}")
    rows = []
    for value in values:
        row: dict = {"value": value, "seeds": sorted(by_value[value]), "measures": {}}
        for measure, read in MEASURES.items():
            for phase in PHASES:
                mine = {s: read(r, phase) for s, r in by_value[value].items()}
                mine = {s: v for s, v in mine.items() if v}
                cell: dict = {"value": Stat.of(sum(v) / len(v) for v in mine.values()).as_dict()}
                if value != baseline:
                    base = {s: read(r, phase) for s, r in by_value[baseline].items()}
                    a, b = _pairs(mine, base, measure, phase, by_value[value], by_value[baseline])
                    difference = paired_difference(a, b)
                    cell["difference"] = {
                        **difference.as_dict(),
                        "verdict": difference.verdict,
                        "seeds_needed": seeds_needed(seed_means(a, b), difference),
                    }
                row["measures"][f"{measure}_{phase}"] = cell
        rows.append(row)
    return {"factor": factor, "baseline": baseline, "rows": rows}


def markdown(result: dict) -> str:
    columns = [f"{m}_{p}" for m in MEASURES for p in PHASES]
    lines = [
        f"{result['factor']}: each value against {result['baseline']} (value − baseline; mean "
        "over seeds, then the paired difference with its 95 % interval over seeds and samples).",
        "",
        "| value | seeds | " + " | ".join(c.replace("_", " ") for c in columns) + " |",
        "|---|---|" + "---|" * len(columns),
    ]
    for row in result["rows"]:
        cells = []
        for column in columns:
            cell = row["measures"][column]
            stat = Stat.from_dict(cell["value"])
            text = "—" if not stat.n else stat.text(3 if column.startswith("eye") else 2)
            d = cell.get("difference")
            if d and d["seeds"] > 1 and d["mean"] == d["low"] == d["high"] == 0:
                text += "; the same in every sample"  # e.g. the eye of a replay: not an effect
            elif d and d["seeds"] > 1:
                told = (
                    "told apart"
                    if d["tells_apart"]
                    else f"not told apart ({d['seeds_needed'] or '—'} seeds would tell)"
                )
                text += f"; {d['mean']:+.3g} [{d['low']:+.3g}, {d['high']:+.3g}], {told}"
            cells.append(text)
        seeds = ", ".join(map(str, row["seeds"]))
        lines.append(f"| {row['value']} | {seeds} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.paired_ablation",
        description=__doc__.split("\n\n")[0],
    )
    parser.add_argument("runs", nargs="+", help="run, replay or sweep folders")
    parser.add_argument(
        "--factor",
        required=True,
        help="the setting that varies, e.g. distance.y, or several comma-separated "
        "(distance.weighting,distance.y)",
    )
    parser.add_argument(
        "--baseline",
        default=None,
        help="its value to compare against (several settings: as the rows name them, e.g. "
        "'distance.weighting=false, distance.y=1.0')",
    )
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--markdown", type=Path, default=None)
    args = parser.parse_args(argv)
    try:
        for path in (args.json, args.markdown):
            if path is not None and (why := file_problem(path)):
                raise ReportError(f"{path}: {why}")
        print(f"[paired_ablation] {args.factor} in {', '.join(args.runs)}", file=sys.stderr)
        result = ablation(args.runs, args.factor, args.baseline)
    except ReportError as exc:
        print(f"paired_ablation: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        sys.exit(2)
    text = markdown(result)
    print(text, end="")
    for path, content in ((args.json, json.dumps(result, indent=1) + "\n"), (args.markdown, text)):
        if path is not None:
            path.write_text(content)
            print(f"[paired_ablation] wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    main()
