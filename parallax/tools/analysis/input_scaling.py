"""`python -m parallax.tools.analysis.input_scaling RUN...`: which input scaling of the distance
network lets the weighting of paper §3.5.1 (eqs. 10–12) do what Tables 4–5 report.

A MATLAB network may scale its inputs per row (mapminmax, the default: it undoes any constant
row weight, so eq. 11 changes nothing), over all inputs at once, or not at all
(``distance.input_scaling`` = per_input, global, none). The paper's weighted 5–20 cm row beats
its unweighted one in all six cells of Tables 4–5, so a scaling under which the weighting cannot
act is ruled out by the paper's own results. This replays (parallax-replay: the same eye
movements, so every comparison is paired) each finished run under each scaling, without the
weighting and with it for each y, and scores every replay three ways, each before and after §5's
perturbation:

- ``queue``: the network on its own queue S at the end of the phase (the paper's probable
  scoring of Tables 4–5);
- ``held_out``: the greedy eye on the held-out photographs of the run's parallax-eval files, one
  per grid distance (ours);
- ``online``: each s predicted before it is learnt, over the trainer's window.

It prints and writes each setting's mean ± sd over the runs, and the weighting's effect
(weighted − unweighted) under each scaling as a paired difference with its 95 % interval
(parallax.tools.report.paired). ``--set KEY=VALUE`` applies a replayable setting to every replay
(e.g. ``distance.warm_start=false``).

    python -m parallax.tools.analysis.input_scaling docs/results/runs/paper \\
        --experiment paper_multi_5_20_weighted --set distance.warm_start=false \\
        --json docs/results/input_scaling.json --markdown docs/results/input_scaling.md
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from tqdm import tqdm

from parallax.checkpoint import BEFORE_PERTURBATION_NAME, CHECKPOINT_NAME
from parallax.config import run_name
from parallax.distance.settings import INPUT_SCALINGS
from parallax.tools.replay import ReplayError, find_sources, replay
from parallax.tools.report.groups import Stat
from parallax.tools.report.paired import paired_difference, seed_means, seeds_needed
from parallax.writable import file_problem

MEASURES = ("queue", "held_out", "online")
PHASES = ("before", "after")
DEFAULT_Y = (0.5, 1.0, 2.0)
UNWEIGHTED = "unweighted"


def weighting_label(y: float | None) -> str:
    return UNWEIGHTED if y is None else f"y={y:g}"


def combo_overrides(scaling: str, y: float | None, common: Sequence[str]) -> list[str]:
    weighting = ["distance.weighting=false"] if y is None else ["distance.weighting=true"]
    weighting += [] if y is None else [f"distance.y={y:g}"]
    return [*common, f"distance.input_scaling={scaling}", *weighting]


def _queue_errors(learner) -> list[float]:
    found = None if learner is None else learner.queue_predictions()
    if found is None:
        return []
    predicted, truth = (np.asarray(t.cpu(), dtype=np.float64) for t in found)
    return (100.0 * np.abs(predicted - truth) / truth).tolist()


def _online_errors(tracker) -> list[float]:
    if tracker is None:
        return []
    return [100.0 * abs(p[0] - p[1]) / p[1] for p in tracker.pairs]


def _held_out_errors(evals: dict, perturbed: bool) -> list[float]:
    """Per grid distance, the eval of the run's own kind of held-out photographs."""
    for evaluation in evals.values():
        stimuli = evaluation.get("stimuli") or {}
        if (
            bool(evaluation.get("perturbed")) == perturbed
            and stimuli.get("split") == "heldout"
            and not evaluation.get("stimuli_overrides")
            and "distance" in evaluation
        ):
            return list(evaluation["distance"]["per_distance"].values())
    return []


def replay_errors(run: Path, overrides: list[str]) -> dict:
    """One replay's per-sample errors (%) by measure and phase, and its fits' figures."""
    result = replay(run, overrides)
    checkpoints = result.get("checkpoints", {})
    final = checkpoints.get(CHECKPOINT_NAME, (None, None, None))
    before = checkpoints.get(BEFORE_PERTURBATION_NAME, (None, None, None))
    max_fail = int(result["config"].distance.max_fail)
    fits = result.get("fits", [])
    unchanged = sum(1 for _, epochs, stopped in fits if stopped and epochs == max_fail)
    return {
        "queue": {"before": _queue_errors(before[0]), "after": _queue_errors(final[0])},
        "held_out": {
            "before": _held_out_errors(result["evals"], False),
            "after": _held_out_errors(result["evals"], True),
        },
        "online": {"before": _online_errors(before[1]), "after": _online_errors(final[1])},
        "fits": len(fits),
        "stopped_at_max_fail_from_the_start": unchanged,
    }


def _run_one(job: tuple[Path, str, float | None, list[str], Path | None]) -> tuple:
    run, scaling, y, common, cache = job
    overrides = combo_overrides(scaling, y, common)
    kept = None if cache is None else cache / f"{run.name}__{run_name(','.join(overrides))}.json"
    if kept is not None and kept.is_file():
        return run, scaling, y, json.loads(kept.read_text())
    found = replay_errors(run, overrides)
    if kept is not None:  # written whole, so that an interrupted study resumes from it
        kept.parent.mkdir(parents=True, exist_ok=True)
        partial = kept.with_suffix(".part")
        partial.write_text(json.dumps(found))
        partial.replace(kept)
    return run, scaling, y, found


def study(
    runs: Sequence[Path],
    scalings: Sequence[str] = INPUT_SCALINGS,
    ys: Sequence[float] = DEFAULT_Y,
    common: Sequence[str] = (),
    jobs: int = 1,
    cache: Path | None = None,
) -> dict:
    """Every (run, scaling, weighting) replayed; the table of totals and the paired effects.
    ``cache``: a folder keeping each replay's errors, read instead of replaying again."""
    settings = [(s, y) for s in scalings for y in (None, *ys)]
    work = [(run, s, y, list(common), cache) for run in runs for s, y in settings]
    errors: dict[tuple[str, str], dict[Path, dict]] = {}
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        done = pool.map(_run_one, work) if jobs > 1 else map(_run_one, work)
        for run, scaling, y, found in tqdm(done, total=len(work), desc="replays", unit="replay"):
            errors.setdefault((scaling, weighting_label(y)), {})[run] = found
    table = []
    for (scaling, weighting), by_run in errors.items():
        row = {"input_scaling": scaling, "weighting": weighting, "runs": len(by_run)}
        for measure in MEASURES:
            for phase in PHASES:
                totals = [
                    float(np.mean(e[measure][phase])) for e in by_run.values() if e[measure][phase]
                ]
                row[f"{measure}_{phase}"] = _stat(totals)
        fits = sum(e["fits"] for e in by_run.values())
        row["share_of_fits_left_unchanged"] = (
            sum(e["stopped_at_max_fail_from_the_start"] for e in by_run.values()) / fits
            if fits
            else None
        )
        table.append(row)
    effects = []
    for scaling in scalings:
        base = errors[(scaling, UNWEIGHTED)]
        for y in ys:
            weighted = errors[(scaling, weighting_label(y))]
            effect = {"input_scaling": scaling, "weighting": weighting_label(y)}
            for measure in MEASURES:
                for phase in PHASES:
                    a = [weighted[run][measure][phase] for run in runs]
                    b = [base[run][measure][phase] for run in runs]
                    pairs = [(x, z) for x, z in zip(a, b) if x and z]
                    a, b = [x for x, _ in pairs], [z for _, z in pairs]
                    difference = paired_difference(a, b)
                    effect[f"{measure}_{phase}"] = {
                        **difference.as_dict(),
                        "verdict": difference.verdict,
                        "seeds_needed": seeds_needed(seed_means(a, b), difference),
                    }
            effects.append(effect)
    return {
        "runs": [str(run) for run in runs],
        "common_overrides": list(common),
        "settings": table,
        "weighting_effect": effects,
    }


def _stat(values: list[float]) -> dict:
    stat = Stat.of(values)
    return {"mean": stat.mean, "sd": stat.sd, "n": stat.n}


def _cell(stat: dict) -> str:
    if not stat["n"]:
        return "—"
    return f"{stat['mean']:.2f} ± {stat['sd']:.2f}" if stat["n"] > 1 else f"{stat['mean']:.2f}"


def format_markdown(result: dict) -> str:
    columns = [f"{m}_{p}" for m in MEASURES for p in PHASES]
    heads = [c.replace("_", " ") for c in columns]
    lines = [
        "Distance error (%), mean ± sd over the runs "
        f"(n = {len(result['runs'])}); every replay with "
        f"{' '.join(result['common_overrides']) or 'the runs own settings'}:",
        "",
        "| input scaling | weighting | " + " | ".join(heads) + " | fits left unchanged |",
        "|---|---|" + "---|" * len(columns) + "---|",
    ]
    for row in result["settings"]:
        share = row["share_of_fits_left_unchanged"]
        lines.append(
            f"| {row['input_scaling']} | {row['weighting']} | "
            + " | ".join(_cell(row[c]) for c in columns)
            + f" | {'—' if share is None else f'{100 * share:.1f} %'} |"
        )
    lines += [
        "",
        "The weighting's effect, weighted − unweighted (percentage points), paired over the same "
        "eye movements, with its 95 % bootstrap interval over runs and samples:",
        "",
        "| input scaling | weighting | " + " | ".join(heads) + " |",
        "|---|---|" + "---|" * len(columns),
    ]
    for effect in result["weighting_effect"]:
        cells = []
        for column in columns:
            d = effect[column]
            if d["seeds"] == 0 or not math.isfinite(d["mean"]):
                cells.append("—")
                continue
            told = " **told apart**" if d["tells_apart"] else ""
            cells.append(f"{d['mean']:+.2f} [{d['low']:+.2f}, {d['high']:+.2f}]{told}")
        lines.append(
            f"| {effect['input_scaling']} | {effect['weighting']} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.input_scaling", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("runs", nargs="+", help="finished runs, or folders holding them")
    parser.add_argument(
        "--experiment",
        default=None,
        help="only the runs whose folder name starts with "
        "experiment=NAME, (e.g. paper_multi_5_20_weighted)",
    )
    parser.add_argument("--scalings", nargs="+", default=list(INPUT_SCALINGS))
    parser.add_argument("--y", type=float, nargs="+", default=list(DEFAULT_Y))
    parser.add_argument(
        "--set",
        dest="common",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a replayable setting for every replay (repeatable)",
    )
    parser.add_argument("--jobs", type=int, default=1, help="replays side by side")
    parser.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="keep each replay's errors here, and read them instead of replaying again (resume)",
    )
    parser.add_argument("--json", default=None, help="write the result here")
    parser.add_argument("--markdown", default=None, help="write the tables here")
    args = parser.parse_args(argv)
    try:
        for path in (args.json, args.markdown):
            problem = path and file_problem(Path(path))
            if problem:
                raise ReplayError(f"{path}: {problem}")
        unknown = sorted(set(args.scalings) - set(INPUT_SCALINGS))
        if unknown:
            raise ReplayError(f"--scalings: {unknown} not among {list(INPUT_SCALINGS)}")
        runs = find_sources(args.runs)
        if args.experiment:
            runs = [r for r in runs if r.name.startswith(f"experiment={args.experiment},")]
        if not runs:
            raise ReplayError(f"no finished run of experiment {args.experiment} under {args.runs}")
        print(
            f"[input_scaling] {len(runs)} runs × {len(args.scalings)} scalings × "
            f"{1 + len(args.y)} weightings, {args.jobs} at a time",
            flush=True,
        )
        result = study(runs, args.scalings, args.y, args.common, args.jobs, args.cache)
    except (ReplayError, FileNotFoundError, ValueError) as exc:
        print(f"input_scaling: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        sys.exit(2)
    text = format_markdown(result)
    print(text, end="")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
        print(f"[input_scaling] wrote {args.json}")
    if args.markdown:
        Path(args.markdown).write_text(text)
        print(f"[input_scaling] wrote {args.markdown}")


if __name__ == "__main__":
    main()
