"""`python -m parallax.tools.analysis.sensitivity FOLDER...`: what the paper family's numbers rest
on — its eye and distance errors with each open setting switched away from its lineage's value.

The runs are those of ``experiment=sensitivity_<setup>`` (paper_<setup> in a shorter run), each
with at most one switch: an open setting of ``conf/open_setting/`` (``+open_setting=xi_1``),
another of the lineage's step-size sets (``step_sizes=chong``) or another of its dictionary
rates η (``dictionary_rate=alex_p``); ``parallax-replay`` of the lineage's runs gives the rows
that change the distance learner only: ``plain_lm``, MATLAB's first scaling kept
(``matlab_network``), and the family's own network (no input processing, built anew at every
fit; the study's lineage keeps MATLAB's defaults) with each of its two choices alone. A run
belongs to the row whose composed config it equals, its seed and the settings that change no
result aside, so that a run of other settings is never counted in a row.

Each row and set-up shows, as mean ± standard deviation over the seeds: the eye's error of
Tables 2–3 (the last-100-trial mean, averaged over L) before and after §5's perturbation, the
online distance error of Tables 4–5 (total) before and after, and the critic's peak scale
(max over the run of mean |v·φ|; it grows without bound when the actor-critic diverges). A run
the trainer stopped because its policy's numbers were no longer finite (``train.
stop_after_non_finite``, leaving its ``diverged.json``) is a result of its row, not a missing
run: it is counted as diverged, at the first presentation whose numbers were not finite, and adds
its critic's peak and, if it diverged after the perturbation, its figures before it.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
from pathlib import Path

from omegaconf import OmegaConf

from parallax.config import compose, result_settings, run_settings
from parallax.tools.report.groups import Stat
from parallax.tools.report.runs import ReportError, Run, find_run_dirs, load_run, read_metrics
from parallax.writable import file_problem

SETUPS = ("single_5", "multi_5_10")
#: The rows, in the table's order: the lineage's values, then one switch each.
ROWS = {
    "lineage": [],
    "ξ = 1": ["+open_setting=xi_1"],
    "projection": ["+open_setting=projection"],
    "normalised features": ["+open_setting=normalised_features"],
    "reset step learnt": ["+open_setting=reset_step_learnt"],
    "pan kept": ["+open_setting=pan_kept"],
    "step sizes origin": ["step_sizes=origin"],
    "step sizes Chong": ["step_sizes=chong"],
    "step sizes Lukas": ["step_sizes=lukas"],
    "η origin (0.01)": ["dictionary_rate=origin"],
    "η Lukas (0.1)": ["dictionary_rate=lukas"],
    "η Alex P (0.5)": ["dictionary_rate=alex_p"],
    "plain LM (replay)": ["+open_setting=plain_lm"],
    "first fit's scaling kept (replay)": ["+open_setting=matlab_network"],
    "new network each fit (replay)": ["distance.warm_start=false"],
    "no input scaling (replay)": ["distance.input_scaling=none"],
    "the family's network (replay)": ["distance.input_scaling=none", "distance.warm_start=false"],
}
#: A row's cells, in the table's order.
CELLS = (
    "eye_before",
    "eye_after",
    "distance_before",
    "distance_after",
    "critic_peak",
)


def _settings(config: dict) -> dict:
    return result_settings(run_settings(config))


@functools.lru_cache(maxsize=4)
def row_settings(overrides: tuple[str, ...]) -> dict[tuple[str, str], dict]:
    """(row, set-up) → the settings a run of that row and set-up has (``overrides`` added to
    every row, e.g. a shrunken test run's). Kept per ``overrides``: it composes every row (a
    second each), and the experiment files do not change while parallax runs."""
    table = {}
    for setup in SETUPS:
        for row, switch in ROWS.items():
            cfg = compose([f"experiment=sensitivity_{setup}", *switch, *overrides])
            table[(row, setup)] = _settings(OmegaConf.to_container(cfg, resolve=True))
    return table


def critic_peak(run: Run) -> float | None:
    """The largest finite mean |v·φ| a run logged (a replay: its source's, read from the source's
    record, since a replay's keeps only its distance learner's; None if none)."""
    source = (run.summary or {}).get("replayed_from")
    scales = [r.get("policy_critic_scale") for r in read_metrics(Path(source or run.path))]
    scales = [s for s in scales if isinstance(s, (int, float)) and math.isfinite(s)]
    return max(scales) if scales else None


def run_figures(run: Run) -> dict:
    """One run's cells: eye (°) and distance (%) before and after, and the critic's peak."""
    figures: dict = {}
    for phase in ("before", "after"):
        trials = run.last_trials(phase) or {}
        means = [cell["mean"] for cell in trials.values() if cell.get("mean") is not None]
        figures[f"eye_{phase}"] = sum(means) / len(means) if means else None
        figures[f"distance_{phase}"] = (run.online_distance(phase) or {}).get("total")
    figures["critic_peak"] = critic_peak(run)
    return figures


def sensitivity(folders: list[Path], overrides: list[str]) -> dict:
    """The table: {setup: {row: {cell: mean ± sd over seeds, "seeds": runs counted, "diverged":
    [presentation, …]}}}, and the runs left out."""
    wanted = row_settings(tuple(overrides))
    found: dict[tuple[str, str], list[dict]] = {}
    diverged: dict[tuple[str, str], list[int]] = {}
    left_out = []
    for folder in folders:
        for path in find_run_dirs(folder):
            run = load_run(path)
            key = next((k for k, s in wanted.items() if s == _settings(run.config)), None)
            if key is not None and run.diverged is not None:
                diverged.setdefault(key, []).append(run.diverged["unhealthy_since"])
                found.setdefault(key, []).append(run_figures(run))
            elif run.problem is not None or key is None:
                left_out.append(f"{path}: {run.problem or 'settings of no row'}")
            else:
                found.setdefault(key, []).append(run_figures(run))
    table: dict = {setup: {} for setup in SETUPS}
    order = list(ROWS)
    for (row, setup), runs in sorted(found.items(), key=lambda item: order.index(item[0][0])):
        cells = {cell: Stat.of(r.get(cell) for r in runs).as_dict() for cell in CELLS}
        stopped = sorted(diverged.get((row, setup), []))
        table[setup][row] = {**cells, "seeds": len(runs), "diverged": stopped}
    return {"table": table, "left_out": left_out}


def _cell(value: dict, digits: int) -> str:
    return Stat.from_dict(value).text(digits)


def _peak(value: dict) -> str:
    """The critic's peak to three significant digits: it spans 0.1 to 1e31."""
    stat = Stat.from_dict(value)
    if stat.n == 0:
        return "—"
    return f"{stat.mean:.3g}" + (f" ± {stat.sd:.3g}" if stat.n >= 2 else "")


def format_table(result: dict) -> str:
    lines = []
    for setup, rows in result["table"].items():
        if not rows:
            continue
        lines += [
            f"sensitivity_{setup}:",
            "",
            "| row | seeds | diverged at | eye before (°) | eye after (°) | distance before (%) "
            "| distance after (%) | critic peak |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for row, cells in rows.items():
            where = ", ".join(f"presentation {p}" for p in cells["diverged"]) or "—"
            lines.append(
                f"| {row} | {cells['seeds']} | {where} | {_cell(cells['eye_before'], 3)} | "
                f"{_cell(cells['eye_after'], 3)} | {_cell(cells['distance_before'], 2)} | "
                f"{_cell(cells['distance_after'], 2)} | {_peak(cells['critic_peak'])} |"
            )
        lines.append("")
    lines += [f"left out: {entry}" for entry in result["left_out"]]
    return "\n".join(lines)


def _fail(message: str) -> None:
    print(f"sensitivity: error: {message}", file=sys.stderr)
    sys.exit(2)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.sensitivity",
        description=__doc__.split("\n\n")[0],
    )
    parser.add_argument("folders", nargs="+", type=Path, help="sweep folders or run folders")
    parser.add_argument("--json", type=Path, help="also write the table here")
    parser.add_argument("--markdown", type=Path, help="also write the printed tables here")
    parser.add_argument(
        "--override",
        action="append",
        default=[],
        help="a setting every run of the study was given besides its row's (repeatable)",
    )
    args = parser.parse_args(argv)
    for option, path in (("--json", args.json), ("--markdown", args.markdown)):
        problem = file_problem(path) if path is not None else None
        if problem:
            _fail(f"{option} {path}: {problem}")
    try:
        result = sensitivity(args.folders, args.override)
    except (ReportError, ValueError) as exc:  # no runs there, or a setting no config has
        _fail(str(exc).splitlines()[0])
    text = format_table(result)
    print(text)
    if args.markdown is not None:
        args.markdown.write_text(text + "\n")
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return result


if __name__ == "__main__":
    main()
