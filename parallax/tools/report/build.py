"""`build_report`: runs in, the report out — Markdown, figures and results.json.

It puts together what the other modules make: the runs (runs.py), grouped over seeds
(groups.py), matched to the paper's tables (selection.py), the tables (tables.py) and the
figures (figures.py).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hydra.errors import HydraException
from omegaconf.errors import OmegaConfBaseException

from parallax.tools.console import header, progress
from parallax.tools.report.figures import (
    Figures,
    figure_ablation,
    figure_distance,
    figure_mae_curves,
    group_curves,
    group_eyes,
    replays,
)
from parallax.tools.report.groups import (
    default_flat_config,
    find_factors,
    group_runs,
    json_ready,
    label_groups,
)
from parallax.tools.report.runs import ReportError, Run, find_run_dirs, load_run, relpath
from parallax.tools.report.selection import parse_preferences, select_paper_groups
from parallax.tools.report.tables import (
    ablation_rows,
    ablation_table,
    distance_table,
    eye_movement_table,
    generalisation_table,
    md_table,
    overview_table,
    scoring_key,
)

TABLE_CHOICES = ("all", "paper", "ablation")


def _run_record(run: Run) -> dict:
    """What results.json keeps of one run: the numbers the tables are made from."""
    summary = run.summary or {}
    return {
        "dir": relpath(run.path),
        "seed": run.seed,
        "presentations": summary.get("presentations"),
        "steps": summary.get("steps"),
        "wall_time_s": (summary.get("timing") or {}).get("wall_time_s"),
        "mae": summary.get("mae"),
        "mae_per_position": summary.get("mae_per_position"),
        "last_trials_before": run.last_trials("before"),
        "last_trials_after": run.last_trials("after"),
        "distance_online_before": run.online_distance("before"),
        "distance_online_after": run.online_distance("after"),
        "evals": [
            {
                "file": relpath(e["_path"]),
                "presentations": e.get("presentations"),
                "perturbed": e.get("perturbed"),
                "stimuli_overrides": e.get("stimuli_overrides") or [],
                "split": (e.get("stimuli") or {}).get("split", "heldout"),
                "textures_per_distance": int(e.get("textures_per_distance") or 1),
                "distance_by_range": (e.get("distance") or {}).get("by_range"),
                "trials": (e.get("distance") or {}).get("trials"),
                "between_grid_by_range": (e.get("distance_between_grid") or {}).get("by_range"),
                "between_trials": (e.get("distance_between_grid") or {}).get("trials"),
                "mae": e.get("mae"),
            }
            for e in run.evals
        ],
    }


def ablation_defaults(runs: Sequence[Run]) -> dict:
    """The settings an ablation's values are compared with (its baseline): where every finished
    run replays another (parallax-replay), the settings of the first run replayed, which the
    replays vary; else the shipped default configuration."""
    finished = [r for r in runs if r.problem is None]
    sources = {(r.summary or {}).get("replayed_from") for r in finished}
    if finished and None not in sources:
        try:
            source = load_run(Path(sorted(sources)[0]))
        except (OSError, OmegaConfBaseException, ReportError):
            source = None  # a source moved or unreadable: the shipped defaults
        if source is not None and source.problem is None:
            return source.flat
    try:
        return default_flat_config()
    except (HydraException, OmegaConfBaseException) as exc:
        # a shipped config that no longer composes must not hide the results
        print(
            f"parallax-report: warning: cannot compose the default config ({exc}); "
            "ablation baselines are the most common values",
            file=sys.stderr,
        )
        return {}


def build_report(
    paths: Sequence[str | Path],
    out: Path | None = None,
    name: str = "README.md",
    title: str = "parallax results",
    tables: str = "all",
    notes: str | None = None,
    prefer: Sequence[str] = (),
) -> tuple[str, dict]:
    """Read the runs below `paths`; write Markdown, figures and JSON into `out` (if given).
    ``prefer``: KEY=VALUE settings that decide which group fills a paper table's cell where
    several fit (e.g. two weighted 5–20 cm groups with different y)."""
    preferences = parse_preferences(prefer)
    if tables not in TABLE_CHOICES:
        raise ReportError(f"--tables must be one of {', '.join(TABLE_CHOICES)}, got {tables!r}")
    run_dirs = list(dict.fromkeys(p.resolve() for path in paths for p in find_run_dirs(path)))
    header(
        "parallax-report",
        f"{tables} tables from {len(run_dirs)} job directories below {', '.join(map(str, paths))}",
        output=(out.resolve() / name) if out is not None else "the Markdown only, printed",
    )
    runs = [load_run(p) for p in progress(run_dirs, desc="reading runs", unit="run", leave=False)]
    failed = [r for r in runs if r.problem is not None]
    groups, duplicates = group_runs(runs)
    factors = find_factors(groups, ablation_defaults(runs))
    label_groups(groups, factors)

    stem = Path(name).stem
    figures = Figures(out, "" if stem.lower() == "readme" else f"{stem}_")
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {
        "title": title,
        "inputs": [relpath(p) for p in paths],
        "groups": [],
        "failed": [],
        "duplicates": [],
        "paper": None,
        "ablations": [],
    }
    md: list[str] = [
        f"# {title}",
        "",
        f"Made by `parallax-report` from {len(runs)} job directories in "
        + ", ".join(f"`{relpath(p)}`" for p in paths)
        + f": {sum(g.n for g in groups)} finished runs in {len(groups)} groups, "
        f"{len(failed)} failed or unfinished, {len(duplicates)} duplicates left out. "
        "Numbers are mean ± sample sd over seeds (n seeds).",
        "",
    ]
    if notes:
        md += [notes.strip(), ""]

    curves = {g.gid: group_curves(g) for g in groups}
    for g in groups:
        results["groups"].append(
            {
                "id": g.gid,
                "label": g.label,
                "settings": json_ready(g.settings),
                "n": g.n,
                "weighting_effective": g.weighting_effective,
                "runs": [_run_record(r) for r in g.runs],
            }
        )

    if groups:
        md += ["## Runs", "", overview_table(groups), ""]

    selection = select_paper_groups(groups, preferences)
    if tables in ("all", "paper") and not selection.empty:
        paper_data: dict[str, Any] = {"notes": selection.notes}
        md += ["## The paper's tables, ours beside theirs", ""]
        for phase, key in (("before", "table2"), ("after", "table3")):
            text, data = eye_movement_table(selection, phase)
            md += [text, ""]
            paper_data[key] = data
        for phase, key in (("before", "table4"), ("after", "table5")):
            text, data = distance_table(selection, phase)
            md += [text, ""]
            paper_data[key] = data
        for scoring in ("queue", "trained_eye"):
            for phase, number in (("before", 4), ("after", 5)):
                # the paper's probable scorings, where the runs record them
                text, data = distance_table(selection, phase, scoring=scoring)
                if data["compared"]:
                    md += [text, ""]
                paper_data[scoring_key(number, scoring)] = data
        if selection.notes:
            md += (
                ["Choices where several groups fit a cell:", ""]
                + [f"- {n}" for n in selection.notes]
                + [""]
            )
        results["paper"] = paper_data
        figure_md = []
        for _number, (phase, caption) in enumerate(
            (
                ("before", "Fig. 10: error against distance"),
                ("after", "Fig. 11: after the perturbation"),
            ),
            10,
        ):
            name_png = figure_distance(figures, selection, groups, phase)
            if name_png:
                figure_md.append(f"![{caption}]({name_png})")
        if out is not None and not figure_md:
            figure_md.append(
                "(No Fig. 10–11: no run has an eval.json for that phase; run `parallax-eval RUN`.)"
            )
        md += figure_md + [""]

    generalisation = generalisation_table(groups)
    if generalisation is not None and tables in ("all", "paper"):
        md += [
            "## Held-out textures and distances between the grid points",
            "",
            generalisation[0],
            "",
        ]
        results["generalisation"] = generalisation[1]

    if tables in ("all", "ablation") and factors:
        md += ["## Ablations", ""]
        in_a_table: set[str] = set()
        for factor in factors:
            rows = ablation_rows(factor, factors, groups)
            if len(rows) < 2:
                continue
            text, data = ablation_table(factor, rows)
            in_a_table.update(g.gid for g in rows)
            md += [text, ""]
            for png in figure_ablation(figures, factor, rows, curves):
                md.append(f"![{factor.key}]({png})")
            md.append("")
            results["ablations"].append(data)
        left_out = [g for g in groups if g.gid not in in_a_table]
        if left_out:
            md += [
                "Groups that differ from the baselines in more than one setting (in the Runs table "
                "only): " + "; ".join(f"{g.gid} ({g.label})" for g in left_out) + ".",
                "",
            ]

    if out is not None and groups:
        md += [
            "## Eye-movement MAE during training (in the manner of Figs. 7–9)",
            "",
            "Sliding-window MAE (eq. 16): mean over seeds (bold) with ± 1 sd shaded, each lateral "
            "position "
            "as a thin line; the gray dashed line is where the perturbation starts.",
            "",
        ]
        # one figure per set of eye movements, drawn with the runs that made them where they
        # are reported (a replay's are its source's)
        eyes = {g.gid: group_eyes(g) for g in groups}
        owner: dict[frozenset, str] = {}
        for g in sorted(groups, key=replays):
            if curves[g.gid] is not None:
                owner.setdefault(eyes[g.gid], g.gid)
        for g in groups:
            if curves[g.gid] is None:
                continue
            if owner[eyes[g.gid]] != g.gid:
                md += [
                    f"**{g.gid}** — {g.label}: the same eye movements as {owner[eyes[g.gid]]} "
                    "(one replays the other's runs, or both replay the same runs), drawn there.",
                    "",
                ]
                continue
            png = figure_mae_curves(figures, g, curves[g.gid])
            md += [f"**{g.gid}** — {g.label}", "", f"![{g.gid}]({png})", ""]

    md += ["## Failed or unfinished jobs", ""]
    if failed:
        md.append(
            md_table(
                ["directory", "status", "overrides"],
                [[relpath(r.path), r.problem, " ".join(r.overrides) or "—"] for r in failed],
            )
        )
    else:
        md.append("None.")
    md.append("")
    results["failed"] = [
        {"dir": relpath(r.path), "status": r.problem, "overrides": r.overrides} for r in failed
    ]
    if duplicates:
        md += [
            "Duplicates left out (same configuration and seed as a run already counted): "
            + ", ".join(f"`{relpath(r.path)}`" for r in duplicates)
            + ".",
            "",
        ]
        results["duplicates"] = [relpath(r.path) for r in duplicates]

    markdown = "\n".join(md).rstrip() + "\n"
    if out is not None:
        (out / name).write_text(markdown)
        json_name = "results.json" if stem.lower() == "readme" else f"{stem}.json"
        results["figures"] = figures.written
        (out / json_name).write_text(json.dumps(json_ready(results), indent=1) + "\n")
    return markdown, results
