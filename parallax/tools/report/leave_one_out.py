"""What each improvement buys: the recipe on 5–20 cm with weighting (paper §4.2, §5, §6) beside
the recipe less each improvement of docs/improvements.md (``conf/experiment/without_*.yaml``).

    python -m parallax.tools.report.leave_one_out RUN_OR_MULTIRUN_DIR… --out docs/results

Each run is matched to the experiment file whose composed config it has (seed and settings that
never change results aside), so trained runs and parallax-replay's both count. Every row uses the
seeds that it and the recipe share, and each difference is paired by seed: removing an
improvement is worse where the row's number is above the recipe's. Numbers per row, mean ± sd
over seeds:

- eye: Table 2's (Table 3's) statistic, the mean error of the last 100 trials before (after)
  the perturbation, averaged over the 16 lateral positions;
- distance: the frozen model's error on held-out photographs (parallax-eval), Table 4's total
  before the perturbation and Table 5's after it.

Writes leave_one_out.md and leave_one_out.json into --out.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from parallax.config import result_settings
from parallax.tools.experiments import ExperimentError, settings
from parallax.tools.report.groups import Stat, json_ready
from parallax.tools.report.runs import (
    ReportError,
    Run,
    find_run_dirs,
    load_run,
    relpath,
    total_error,
)
from parallax.tools.report.tables import md_table

#: The set-up every row is a variant of.
RECIPE = "recipe_multi_5_20_weighted"
PREFIX = "without_"
EXPERIMENTS = Path(__file__).resolve().parents[3] / "conf" / "experiment"


def _eye(phase: str) -> Callable[[Run], float | None]:
    def value(run: Run) -> float | None:
        trials = run.last_trials(phase)
        if not trials:
            return None
        return statistics.fmean(float(t["mean"]) for t in trials.values())

    return value


def _distance(phase: str) -> Callable[[Run], float | None]:
    def value(run: Run) -> float | None:
        result = run.eval_for(phase)
        return (
            None if result is None else total_error((result.get("distance") or {}).get("by_range"))
        )

    return value


#: (key, column title, value of a run); all lower is better.
METRICS: tuple[tuple[str, str, Callable[[Run], float | None]], ...] = (
    ("eye_before", "eye, Table 2 (deg)", _eye("before")),
    ("eye_after", "eye, Table 3 (deg)", _eye("after")),
    ("distance_before", "distance, Table 4 (%)", _distance("before")),
    ("distance_after", "distance, Table 5 (%)", _distance("after")),
)


def variants(folder: Path = EXPERIMENTS) -> list[str]:
    return sorted(p.stem for p in folder.glob(f"{PREFIX}*.yaml"))


IMPROVEMENTS = EXPERIMENTS.parents[1] / "docs" / "improvements.md"


def section(name: str, folder: Path = EXPERIMENTS, docs: Path = IMPROVEMENTS) -> str:
    """The docs/improvements.md section an experiment file names in its header, with its
    heading: '§4 Weight decay in the Levenberg–Marquardt fit'."""
    found = re.search(r"§(\d+)", (folder / f"{name}.yaml").read_text())
    if not found:
        return ""
    number = found.group(1)
    heading = (
        re.search(rf"^## {number}\. (.+)$", docs.read_text(), re.M) if docs.is_file() else None
    )
    title = "" if heading is None else " " + re.sub(r" \(`[^`]*`\)$", "", heading.group(1))
    return f"§{number}{title}"


def _key(flat: dict) -> tuple:
    return tuple(sorted((k, repr(v)) for k, v in result_settings(flat).items()))


def match_runs(runs: Sequence[Run], names: Sequence[str]) -> dict[str, dict[int, Run]]:
    """Experiment name → seed → its finished run (the first found of a seed)."""
    by_config = {_key(settings(name)): name for name in names}
    matched: dict[str, dict[int, Run]] = {name: {} for name in names}
    for run in runs:
        name = by_config.get(_key(run.flat))
        if name is not None and run.summary is not None:
            matched[name].setdefault(int(run.seed), run)
    return matched


def leave_one_out(paths: Sequence[str | Path]) -> dict:
    names = [RECIPE, *variants()]
    run_dirs = list(dict.fromkeys(p.resolve() for path in paths for p in find_run_dirs(path)))
    runs = [load_run(p) for p in run_dirs]
    matched = match_runs(runs, names)
    recipe = matched[RECIPE]
    rows = []
    for name in names:
        mine = matched[name]
        seeds = sorted(set(mine) & set(recipe))
        row: dict = {
            "experiment": name,
            "section": "" if name == RECIPE else section(name),
            "seeds": seeds,
            "runs": [relpath(mine[s].path) for s in seeds],
        }
        for key, _title, value in METRICS:
            values = [value(mine[s]) for s in seeds]
            row[key] = Stat.of(values).as_dict()
            if name != RECIPE:
                pairs = [
                    (v, value(recipe[s]))
                    for v, s in zip(values, seeds, strict=True)
                    if v is not None and value(recipe[s]) is not None
                ]
                row[f"{key}_change"] = Stat.of(v - r for v, r in pairs).as_dict()
                row[f"{key}_worse"] = [sum(v > r for v, r in pairs), len(pairs)]
        rows.append(row)
    return {"inputs": [relpath(p) for p in paths], "rows": rows}


def _cell(row: dict, key: str) -> str:
    stat = Stat.from_dict(row[key])
    text = stat.text(3 if key.startswith("eye") else 2)
    if f"{key}_change" in row and stat.n:
        change = row[f"{key}_change"]
        worse, n = row[f"{key}_worse"]
        sign = "+" if (change["mean"] or 0) >= 0 else "−"
        text += f" ({sign}{abs(change['mean']):.{3 if key.startswith('eye') else 2}f}, "
        text += f"worse on {worse}/{n})"
    return text


def markdown(result: dict, notes: str | None = None) -> str:
    header = ["experiment", "improvement removed", "seeds"] + [t for _k, t, _v in METRICS]
    table = []
    for row in result["rows"]:
        table.append(
            [
                f"`{row['experiment']}`",
                "none (the recipe)" if row["experiment"] == RECIPE else row["section"],
                ", ".join(map(str, row["seeds"])) or "—",
            ]
            + [_cell(row, key) for key, _t, _v in METRICS]
        )
    lines = [
        "# What each improvement buys",
        "",
        "Made by `python -m parallax.tools.report.leave_one_out` from "
        + ", ".join(f"`{p}`" for p in result["inputs"])
        + ". The recipe on 5–20 cm with weighting "
        f"(`parallax-train experiment={RECIPE}`) and the same less one improvement of "
        "[docs/improvements.md](../improvements.md) (`experiment=without_…`), on the seeds each "
        "row shares with the recipe. Mean ± sd over seeds; in brackets, the mean paired change "
        "from the recipe and on how many seeds the row is worse. Eye: the last 100 trials' mean "
        "error before (Table 2) and after (Table 3) the perturbation, averaged over the lateral "
        "positions. Distance: the frozen models on held-out photographs (`parallax-eval`).",
        "",
    ]
    if notes:
        lines += [notes.strip(), ""]
    lines += [md_table(header, table), ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.leave_one_out", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("paths", nargs="+", metavar="RUN_OR_MULTIRUN_DIR")
    parser.add_argument("--out", default=None, help="folder for leave_one_out.md and .json")
    parser.add_argument("--notes", default=None, help="a Markdown file put above the table")
    args = parser.parse_args(argv)
    try:
        notes = Path(args.notes).read_text() if args.notes else None
        result = leave_one_out(args.paths)
    except (ReportError, ExperimentError, OSError) as exc:
        print(f"leave_one_out: error: {exc}", file=sys.stderr)
        sys.exit(2)
    text = markdown(result, notes)
    if args.out is None:
        print(text, end="")
        return
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "leave_one_out.md").write_text(text)
    (out / "leave_one_out.json").write_text(json.dumps(json_ready(result), indent=1) + "\n")
    print(f"[leave_one_out] wrote {out / 'leave_one_out.md'}")


if __name__ == "__main__":
    main()
