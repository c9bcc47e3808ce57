"""The paper's Tables 2–5 in three columns: the published number, the paper's algorithm run in
parallax — with the settings it leaves open chosen by us (``experiment=unsourced_<setup>``), or
taken from the code it builds on (``experiment=paper_<setup>``, ``--middle paper``) — and ours
(``experiment=recipe_<setup>``); and, for every 5–20 cm model, the evaluations a sceptic would ask
for.

    python -m parallax.tools.report.compare docs/results/unsourced.json docs/results/recipe.json
        --out docs/results
    python -m parallax.tools.report.compare docs/results/paper.json docs/results/recipe.json
        --middle paper --out docs/results

It reads the JSON that `parallax-report --tables paper` wrote for each family (launch/
reproduce.sh makes both), so the three columns come from the same numbers as the two families'
own reports. Writes README.md (or --name) and its JSON (compare.json) into --out.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from parallax.tools.report import paper_results as paper
from parallax.tools.report.groups import Stat, json_ready
from parallax.tools.report.runs import ReportError, total_error
from parallax.tools.report.tables import SCORINGS, md_table, scoring_key


@dataclass(frozen=True)
class Middle:
    """A family of the paper's algorithm, the column between the paper's and ours."""

    #: its name in the tables and the JSON
    key: str
    #: its header in the README's table
    header: str
    #: what it is, for the report's first paragraph
    what: str
    #: the title's words for it
    title: str
    #: the report's sentence on the other family of the paper's algorithm
    other: str


#: ``--middle``: the family of the paper's algorithm shown beside the paper and ours.
MIDDLES = {
    "unsourced": Middle(
        key="unsourced",
        header="paper's algorithm, open settings ours (unsourced_*)",
        what="the unsourced family: the paper's algorithm with the settings it leaves open chosen "
        "by us, `experiment=unsourced_<setup>`",
        title="the paper's algorithm with its open settings chosen by us",
        other="The paper family (`experiment=paper_<setup>`, those settings taken from the code "
        "the paper builds on) is not part of this report.",
    ),
    "paper": Middle(
        key="paper_family",
        header="paper's algorithm, open settings from its lineage (paper_*)",
        what="the paper family: the paper's algorithm with the settings it leaves open taken "
        "from the code it builds on, `experiment=paper_<setup>`",
        title="the paper's algorithm with its open settings from its lineage",
        other="The unsourced family (`experiment=unsourced_<setup>`, those settings chosen by "
        "us) is not part of this report.",
    ),
}
#: The recipe's column and its header in the README's table.
OURS, OURS_HEADER = "ours", "ours (recipe)"
TEXTURES_PHOTOGRAPHS = "held-out photographs"


def _text(stat: Stat, digits: int = 2) -> str:
    return "—" if stat.n == 0 else f"{stat.text(digits)} (n={stat.n})"


def _load(path: str | Path) -> dict:
    path = Path(path)
    try:
        result = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ReportError(f"{path}: {exc}") from None
    if not result.get("paper"):
        raise ReportError(f"{path}: no paper tables (made with parallax-report --tables paper?)")
    return result


#: The distance tables under each scoring (parallax.tools.report.tables.SCORINGS): ours
#: (held-out photographs) and the paper's probable protocol (the network on its own queue, the
#: eye as trained), at the end of each phase.
DISTANCE_KEYS = {s: (scoring_key(4, s), scoring_key(5, s)) for s in SCORINGS}

_NOT_RUN: dict = {
    "paper": {
        k: {"cells": {}, "rows": {}}
        for k in ("table2", "table3", *(k for keys in DISTANCE_KEYS.values() for k in keys))
    },
    "groups": [],
}


def eye_table(families: dict[str, dict], key: str) -> tuple[str, dict, list[dict], Counter]:
    """Table 2 (key 'table2') or 3 ('table3'): per lateral position and column, three cells;
    the cells worse than the paper and, per family, how many cells were compared."""
    header = ["L (cm)"]
    for column in paper.EYE_MOVEMENT_COLUMNS:
        header += [f"{column}: paper", *(f"{column}: {f}" for f in families)]
    rows, data, worse, compared = [], {}, [], Counter()
    for position in paper.TABLE_POSITIONS_CM:
        row = [position]
        for column in paper.EYE_MOVEMENT_COLUMNS:
            published = (paper.TABLE2 if key == "table2" else paper.TABLE3)[column][position]
            row.append("-" if published is None else f"{published[0]:.2f}")
            cell = {"paper": None if published is None else published[0]}
            for family, result in families.items():
                found = result["paper"][key]["cells"].get(column, {}).get(position) or {}
                stat = Stat.from_dict((found.get("ours") or {}).get("mean"))
                row.append("-" if published is None else _text(stat))
                cell[family] = stat.as_dict()
                if published is None or not stat.n:
                    continue
                compared[family] += 1
                if round(stat.mean, 2) > published[0]:
                    excess = f"+{stat.mean - published[0]:.2f}°"
                    text = (
                        f"{column} at {position} cm: {stat.mean:.2f}° against {published[0]:.2f}°"
                    )
                    worse.append({"family": family, "text": text, "excess": excess})
            data.setdefault(column, {})[position] = cell
        rows.append(row)
    return md_table(header, rows), data, worse, compared


def distance_table(families: dict[str, dict], key: str) -> tuple[str, dict, list[dict], Counter]:
    """Table 4 (key 'table4') or 5 ('table5'): per row and range of distances, three cells;
    the cells worse than the paper and, per family, how many cells were compared."""
    published_table = paper.TABLE4 if key.startswith("table4") else paper.TABLE5
    header = ["Simulation"]
    for r in paper.DISTANCE_RANGES:
        title = paper.DISTANCE_RANGE_TITLES[r]
        header += [f"{title}: paper", *(f"{title}: {f}" for f in families)]
    rows, data, worse, compared = [], {}, [], Counter()
    for row_name, published in published_table.items():
        row = [row_name]
        data[row_name] = {}
        for r in paper.DISTANCE_RANGES:
            row.append(f"{published[r]:.2f}")
            cell = {"paper": published[r]}
            for family, result in families.items():
                found = (result["paper"].get(key) or {"rows": {}})["rows"].get(row_name) or {}
                stat = Stat.from_dict((found.get("ours") or {}).get(r))
                row.append(_text(stat))
                cell[family] = stat.as_dict()
                if not stat.n:
                    continue
                compared[family] += 1
                if round(stat.mean, 2) > published[r]:
                    text = (
                        f"{row_name}, {paper.DISTANCE_RANGE_TITLES[r]}: {stat.mean:.2f} % "
                        f"against {published[r]:.2f} %"
                    )
                    excess = f"{stat.mean / published[r]:.2f}×"
                    worse.append({"family": family, "text": text, "excess": excess})
            data[row_name][r] = cell
        rows.append(row)
    return md_table(header, rows), data, worse, compared


#: More cells worse than the paper in one table than this are one line, not a list.
WORSE_LISTED = 4

#: A cell is near the paper when its mean is at most this many times the published number (a
#: cell better than the paper's counts): the paper family's target.
NEAR_FACTOR = 1.5


def near_paper(data: dict, families: Sequence[str]) -> dict[str, dict[str, list[int]]]:
    """Per family: [near, compared] for the eye cells of Tables 2–3 and for the distance totals
    of Tables 4–5 (the cells of ``data`` as :func:`compare` builds them; a cell not run is not
    compared)."""
    cells = {
        "eye": [
            c
            for key in ("table2", "table3")
            for column in data[key].values()
            for c in column.values()
            if c["paper"] is not None
        ],
        **{
            f"distance_totals{'' if scoring == 'held_out' else '_' + scoring}": [
                row["total"] for key in keys for row in data.get(key, {}).values()
            ]
            for scoring, keys in DISTANCE_KEYS.items()
        },
    }
    counts: dict[str, dict[str, list[int]]] = {}
    for family in families:
        for what, found in cells.items():
            run = [c for c in found if c[family]["n"]]
            near = sum(c[family]["mean"] <= NEAR_FACTOR * c["paper"] for c in run)
            counts.setdefault(family, {})[what] = [near, len(run)]
    return counts


def worse_lines(number: int | str, worse: list[dict], compared: Counter) -> list[str]:
    """The Markdown lines of one table's cells worse than the paper: each cell of a family with
    few, one summary line for a family with many (the JSON keeps every cell)."""
    lines = []
    for family in compared:
        mine = [w for w in worse if w["family"] == family]
        if len(mine) > WORSE_LISTED:
            excess = sorted((w["excess"] for w in mine), key=lambda e: float(e.strip("+°×")))
            lines.append(
                f"- {family}, Table {number}: {len(mine)} of {compared[family]} cells "
                f"({excess[0]} to {excess[-1]})"
            )
        else:
            lines += [f"- {family}, Table {number}, {w['text']} ({w['excess']})" for w in mine]
    return lines


def _evaluated_on(evaluation: dict) -> str:
    """What an evaluation of the report's records ran on: the kind of textures and how many per
    distance, so that no row pools two."""
    kind = _kind(evaluation.get("stimuli_overrides") or [])
    per_distance = int(evaluation.get("textures_per_distance") or 1)
    return kind if per_distance == 1 else f"{kind}, {per_distance} per distance"


def _kind(overrides: Sequence[str]) -> str:
    if not overrides:
        return TEXTURES_PHOTOGRAPHS
    settings = dict(o.split("=", 1) for o in overrides)
    if "dir" in {k.rsplit(".", 1)[-1] for k in settings}:
        folder = next(v for k, v in settings.items() if k.endswith(".dir"))
        return f"photographs of other subjects ({Path(folder).name}/)"
    return settings.get("env.stimuli.kind", settings.get("env.stimuli.source", " ".join(overrides)))


def sceptic_table(families: dict[str, dict]) -> tuple[str, list[dict]]:
    """Every 5–20 cm model (Tables 4–5's rows) of each family, before and after the
    perturbation: held-out photographs on the grid and between its points, and textures of
    other kinds; mean ± sd over seeds and the trials behind each number (per seed)."""
    rows, data = [], []
    for family, result in families.items():
        groups = {g["id"]: g for g in result.get("groups", [])}
        for row_name in (paper.NO_WEIGHTING_5_20, paper.WEIGHTING_5_20):
            found = result["paper"]["table5"]["rows"].get(row_name) or {}
            group = groups.get(found.get("group"))
            if group is None:
                continue
            for perturbed, phase in ((False, "before"), (True, "after")):
                measured: dict[str, dict[str, list]] = {}
                for run in group["runs"]:
                    for e in run.get("evals", []):
                        # the eye as trained (the training split) has tables of its own
                        if bool(e.get("perturbed")) != perturbed or e.get("split") == "train":
                            continue
                        kind = _evaluated_on(e)
                        parts = [("grid", "distance_by_range", "trials")]
                        if e.get("between_trials"):
                            parts.append(("between", "between_grid_by_range", "between_trials"))
                        for part, by_range, trials in parts:
                            slot = measured.setdefault(f"{kind}, {part}", {"v": [], "t": []})
                            slot["v"].append(total_error(e.get(by_range)))
                            slot["t"].append(e.get(trials))
                for what, slot in sorted(measured.items()):
                    stat = Stat.of(slot["v"])
                    trials = sorted({t for t in slot["t"] if t is not None})
                    rows.append(
                        [
                            family,
                            row_name,
                            phase,
                            what,
                            _text(stat),
                            "/".join(map(str, trials)) or "—",
                        ]
                    )
                    data.append(
                        {
                            "family": family,
                            "model": row_name,
                            "phase": phase,
                            "textures": what,
                            "total": stat.as_dict(),
                            "trials_per_seed": trials,
                        }
                    )
    header = ["family", "model", "perturbation", "textures", "distance error (%)", "trials"]
    return md_table(header, rows), data


#: The README's results table sits between these two lines; `--readme` rewrites it.
README_BEGIN = "<!-- results table: python -m parallax.tools.report.compare --readme README.md -->"
README_END = "<!-- end of the results table -->"


def _eye_range(cells: dict, column: str, family: str) -> str:
    means = [
        c[family]["mean"]
        for c in cells[column].values()
        if c["paper"] is not None and c.get(family) and c[family]["n"]
    ]
    if not means:
        return "not yet run"
    low, high = f"{min(means):.2f}", f"{max(means):.2f}"
    return f"{low}°" if low == high else f"{low}–{high}°"


def _published_range(table: dict, column: str) -> str:
    values = [v[0] for v in table[column].values() if v is not None]
    return f"{min(values):.2f}–{max(values):.2f}°"


def readme_table(data: dict) -> str:
    """The README's summary: Tables 2–3 as ranges over the lateral positions, Tables 4–5's
    totals; the paper, the paper's algorithm (``data["middle"]``'s family), ours."""
    middle = MIDDLES[data["middle"]]
    families = (middle.key, OURS)
    header = ["", "paper (published)", middle.header, OURS_HEADER]
    rows = []
    for key, table, what in (
        ("table2", paper.TABLE2, "Table 2: eye error"),
        ("table3", paper.TABLE3, "Table 3: eye error after the perturbation"),
    ):
        for column, name in zip(
            paper.EYE_MOVEMENT_COLUMNS,
            (
                "single positions 5…20 cm",
                "multiple positions 5–10 cm",
                "multiple positions 5–20 cm",
            ),
            strict=True,
        ):
            rows.append(
                [f"{what}, {name}", _published_range(table, column)]
                + [_eye_range(data[key], column, f) for f in families]
            )
    for key, what in (("table4", "Table 4: distance error"), ("table5", "Table 5: after it")):
        for row_name, cells in data.get(key, {}).items():
            total = cells["total"]
            rows.append(
                [f"{what}, {row_name}", f"{total['paper']:.2f} %"]
                + [
                    "not yet run"
                    if not total[f]["n"]
                    else f"{Stat.from_dict(total[f]).text()} % (n={total[f]['n']})"
                    for f in families
                ]
            )
    for scoring, words in SCORINGS.items():
        totals = [
            cells["total"] for key in DISTANCE_KEYS[scoring] for cells in data.get(key, {}).values()
        ]
        if scoring == "held_out" or not any(t[f]["n"] for t in totals for f in families):
            continue  # held out: the rows above; else no family recorded this scoring yet
        rows.append(
            [f"Tables 4–5 {words}: the six totals", _total_range(totals, "paper")]
            + [_total_range(totals, f) for f in families]
        )
    return md_table(header, rows)


def _total_range(totals: list[dict], family: str) -> str:
    """The range of the totals' means (the paper's printed totals), with the seeds behind them."""
    if family == "paper":
        low, high = min(t["paper"] for t in totals), max(t["paper"] for t in totals)
        return f"{low:.2f}–{high:.2f} %"
    cells = [t[family] for t in totals if t[family]["n"]]
    if not cells:
        return "not yet run"
    means, seeds = [c["mean"] for c in cells], sorted({c["n"] for c in cells})
    n = f"n={seeds[0]}" if len(seeds) == 1 else f"n={seeds[0]}–{seeds[-1]}"
    low, high = f"{min(means):.2f}", f"{max(means):.2f}"
    span = low if low == high else f"{low}–{high}"
    return f"{span} % ({len(cells)} of {len(totals)}, {n})"


def write_readme_table(
    readme: Path, table: str, begin: str = README_BEGIN, end: str = README_END
) -> None:
    """Put ``table`` between the README's marker lines ``begin`` and ``end``."""
    text = readme.read_text()
    if begin not in text or end not in text:
        raise ReportError(f"{readme}: no lines {begin!r} … {end!r} to write between")
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    readme.write_text(f"{head}{begin}\n\n{table}\n\n{end}{tail}")


def readme_block(readme: Path) -> str:
    """The table now between the README's marker lines."""
    text = readme.read_text()
    return text.split(README_BEGIN, 1)[1].split(README_END, 1)[0].strip()


def compare(
    middle_json: str | Path | None, ours_json: str | Path, middle: str = "unsourced"
) -> tuple[str, dict]:
    """The report and its data: ``middle_json`` is parallax-report's JSON of the family
    ``middle`` (a key of MIDDLES; None: not run, an empty column), ``ours_json`` the recipe's."""
    family = MIDDLES[middle]
    shown = _load(middle_json) if middle_json is not None else _NOT_RUN
    families = {family.key: shown, OURS: _load(ours_json)}
    stem = Path(middle_json or f"{middle}.json").stem
    # the leave-one-out report (launch/reproduce.sh without) sits beside the families' JSON
    leave_one_out = (
        "what each improvement buys is in [leave_one_out.md](leave_one_out.md)."
        if (Path(ours_json).parent / "leave_one_out.md").exists()
        else "what each improvement buys (`bash launch/reproduce.sh without`) is not yet made."
    )
    md = [
        f"# The paper, {family.title}, and ours: Tables 2–5",
        "",
        "Made by `python -m parallax.tools.report.compare` from "
        f"{f'`{middle_json}`' if middle_json else 'nothing'} ({family.what}) and "
        f"`{ours_json}` (our recipe, `experiment=recipe_<setup>`), which `parallax-report` "
        f"wrote from the runs of `bash launch/reproduce.sh`. {family.other} Cells: mean ± sd "
        "over seeds (n seeds); the paper's published number beside them. Each family's own "
        "report, with every run, its figures in the manner of Figs. 7–11 and its failed jobs, "
        f"is the Markdown beside its JSON ([{stem}.md]({stem}.md), [{Path(ours_json).stem}.md]"
        f"({Path(ours_json).stem}.md)); {leave_one_out}",
        "",
    ]
    data: dict = {"inputs": [str(middle_json), str(ours_json)], "middle": middle}
    worse_all: list[str] = []
    worse_md: list[str] = []
    for key, number, what, table in (
        (
            "table2",
            2,
            "eye-movement error of the last 100 trials (deg), before the perturbation",
            eye_table,
        ),
        (
            "table3",
            3,
            "the same after the perturbation (camera rotated 15°, blur σ = 2)",
            eye_table,
        ),
        (
            "table4",
            4,
            "distance-estimation error (%), held-out photographs, before",
            distance_table,
        ),
        ("table5", 5, "the same after the perturbation", distance_table),
        (
            "table4_queue",
            "4 (on its own queue)",
            "distance-estimation error (%) under the paper's probable scoring (the network on "
            "its own queue at the end of the phase), before",
            distance_table,
        ),
        ("table5_queue", "5 (on its own queue)", "the same after the perturbation", distance_table),
        (
            "table4_trained_eye",
            "4 (the eye as trained)",
            "distance-estimation error (%) under the paper's probable scoring (the eye as it "
            "trained, its learning policy on the training photographs at every grid distance, "
            "read by the network as the phase left it), before",
            distance_table,
        ),
        (
            "table5_trained_eye",
            "5 (the eye as trained)",
            "the same after the perturbation",
            distance_table,
        ),
    ):
        text, cells, worse, compared = table(families, key)
        md += [f"**Table {number}** — {what}.", "", text, ""]
        data[key] = cells
        worse_all += [f"{w['family']}, Table {number}, {w['text']} ({w['excess']})" for w in worse]
        worse_md += worse_lines(number, worse, compared)
    md += ["## Cells worse than the paper", ""]
    md += worse_md or ["None."]
    md += [""]
    data["worse_than_paper"] = worse_all
    near = near_paper(data, list(families))
    md += [
        f"## Within {NEAR_FACTOR:g}× of the paper",
        "",
        f"Cells whose mean is at most {NEAR_FACTOR:g} times the paper's published number (a cell "
        "better than the paper's counts), of the cells run.",
        "",
        md_table(
            [
                "family",
                "eye cells, Tables 2–3",
                *(f"distance totals, Tables 4–5 ({words})" for words in SCORINGS.values()),
            ],
            [
                [family, *(f"{k} of {n}" for k, n in counts.values())]
                for family, counts in near.items()
            ],
        ),
        "",
    ]
    data["near_paper"] = {"factor": NEAR_FACTOR, "families": near}
    text, sceptic = sceptic_table(families)
    md += [
        "## Every 5–20 cm model on held-out textures",
        "",
        "Frozen models (`parallax-eval`): held-out photographs on the grid and between its "
        "points, and textures of other kinds; the total distance error, mean ± sd over seeds, "
        "and the trials per seed behind it.",
        "",
        text,
        "",
    ]
    data["sceptic"] = sceptic
    return "\n".join(md), data


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.compare", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument(
        "middle_json",
        help="parallax-report's JSON of the family of the paper's algorithm ('-': not run)",
    )
    parser.add_argument("ours_json", help="parallax-report's JSON of the recipe family")
    parser.add_argument(
        "--middle",
        choices=sorted(MIDDLES),
        default="unsourced",
        help="which family of the paper's algorithm middle_json holds",
    )
    parser.add_argument("--out", default=None, help="folder for the Markdown and compare.json")
    parser.add_argument("--name", default="README.md", help="file name of the Markdown")
    parser.add_argument("--notes", default=None, help="a Markdown file put under the title")
    parser.add_argument(
        "--readme",
        default=None,
        help="also rewrite the summary table of this README (between its marker lines)",
    )
    args = parser.parse_args(argv)
    try:
        text, data = compare(
            None if args.middle_json == "-" else args.middle_json, args.ours_json, args.middle
        )
        if args.readme is not None:
            readme = Path(args.readme)
            if README_BEGIN not in readme.read_text():
                raise ReportError(f"{readme}: no line {README_BEGIN!r} to write after")
        if args.notes:
            head, _, rest = text.partition("\n\n")
            text = "\n\n".join([head, Path(args.notes).read_text().strip(), rest])
    except (ReportError, OSError) as exc:
        print(f"compare: error: {exc}", file=sys.stderr)
        sys.exit(2)
    if args.out is None:
        print(text, end="")
    else:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / args.name).write_text(text.rstrip() + "\n")
        (out / "compare.json").write_text(json.dumps(json_ready(data), indent=1) + "\n")
        print(f"[compare] wrote {out / args.name}")
    if args.readme is not None:
        write_readme_table(Path(args.readme), readme_table(data))
        print(f"[compare] wrote the results table of {args.readme}")


if __name__ == "__main__":
    main()
