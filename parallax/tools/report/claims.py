"""`python -m parallax.tools.report.claims`: the paper's claims, each with a verdict, from the
committed run records (docs/results/runs, read by parallax.tools.report.claim_runs; the claims
and their comparisons are in parallax.tools.report.claim_texts).

Writes claims.md and claims.json into --out (default docs/results), and with --readme the
one-line-per-claim list between the README's marker lines. :data:`RULES` says how a verdict is
decided.
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallax.tools.report.claim_runs import FAMILIES, RECORDS, Records, pairs
from parallax.tools.report.claim_texts import CLAIMS, ROBUSTNESS_MARGIN, Comparison
from parallax.tools.report.compare import write_readme_table
from parallax.tools.report.groups import json_ready
from parallax.tools.report.paired import paired_difference, seed_means, seeds_needed
from parallax.tools.report.runs import ReportError, Run, relpath
from parallax.tools.report.tables import md_table
from parallax.writable import file_problem

COMMAND = "python -m parallax.tools.report.claims"
README_BEGIN = f"<!-- claims: {COMMAND} --readme README.md -->"
README_END = "<!-- end of the claims -->"
FAMILY_TITLES = {"paper_family": "paper family (paper_*)", "ours": "ours (recipe_*)"}
REPRODUCED, NOT_REPRODUCED, REVERSED = "reproduced", "not reproduced", "reversed"
RUNS_MISSING, NO_RECORDS = "runs missing", "no records"
#: Sides whose paired samples all agree this closely (relative to b) are the same numbers.
SAME_NUMBERS = 1e-5
RULES = f"""Each comparison sets two sides a and b against each other in both families (the paper's
algorithm, `paper_*`, and ours, `recipe_*`): the paper's own a − b where its tables print both,
each family's a and b (means over the paired seeds), and the paired difference a − b with its
95 % interval, a two-level bootstrap over the seeds and, within each seed, its paired samples
(parallax.tools.report.paired). The verdict of a comparison:

- where the paper states a difference (a < b, or a > b): **{REPRODUCED}** when the interval
  excludes zero on the paper's side, **{REVERSED}** when it excludes zero on the other side, else
  **{NOT_REPRODUCED}**, with the seeds a paired test would need to tell the observed mean
  difference from zero at the 5 % level with 80 % power (from the larger of the seeds' spread
  and the spread the interval implies, and more than the seeds it rests on);
- where the paper states robustness (a, after §5's perturbation, is similar to b, before it): a
  non-inferiority test with a margin of {{margin:.0%}} of b: **{REPRODUCED}** when the interval's
  upper end is below the margin (after is worse by less than the margin, at 95 %), **{REVERSED}**
  when its lower end is above it, else **{NOT_REPRODUCED}**;
- **{RUNS_MISSING}**: one side has no finished runs (the commands make them); **{NO_RECORDS}**:
  its runs do not record that measure.

With few seeds the bootstrap's interval is too narrow rather than too wide (three seeds give at
most ten distinct resamples of the top level): read "{REPRODUCED}" on three seeds as likely, not
as settled. A claim is {REPRODUCED} when every comparison that has records is, {REVERSED} when
one is and none is {REPRODUCED}, else {NOT_REPRODUCED}; the count of comparisons follows.

Pairing: parallax-eval draws the photograph of each grid distance from the run's `env.stimuli`
settings alone (the i-th distance gets the i-th held-out photograph, whatever the seed or the
set-up), so two evaluations with the same texture settings saw the same photograph at each
distance and are paired photograph by photograph; evaluations on other textures are never
paired. Eye errors pair by seed and lateral position; measures with one value per run pair by
seed."""


@dataclass
class Found:
    """One comparison in one family: the paired values, the runs read, what was chosen."""

    seeds: list[int]
    a: list[list[float]]
    b: list[list[float]]
    runs_a: list[Run]
    runs_b: list[Run]
    chosen: list[str]
    unmeasured: list[str]  # the sides with no values in any seed


def find(comparison: Comparison, records: Records, prefix: str) -> Found:
    values_a, runs_a, chosen_a = comparison.a.values(records, prefix)
    values_b, runs_b, chosen_b = comparison.b.values(records, prefix)
    seeds, a, b = pairs(values_a, values_b)
    unmeasured = [
        side.label
        for side, values in ((comparison.a, values_a), (comparison.b, values_b))
        if not values
    ]
    return Found(seeds, a, b, runs_a, runs_b, [c for c in (chosen_a, chosen_b) if c], unmeasured)


def judge(comparison: Comparison, found: Found) -> dict:
    """The family's cell of a comparison: its sides' means, the paired difference, the verdict."""
    cell: dict = {"seeds": found.seeds, "chosen": found.chosen}
    if not found.runs_a or not found.runs_b:
        cell["verdict"] = RUNS_MISSING
        cell["why"] = "no finished runs of " + " or ".join(
            side.label
            for side, runs in ((comparison.a, found.runs_a), (comparison.b, found.runs_b))
            if not runs
        )
        return cell
    if not found.seeds:
        missing = " or ".join(found.unmeasured) or "one side in any seed that the other has"
        cell["verdict"], cell["why"] = NO_RECORDS, f"no values of {missing}"
        return cell
    cell["a"] = float(np.mean([np.mean(v) for v in found.a]))
    cell["b"] = float(np.mean([np.mean(v) for v in found.b]))
    difference = paired_difference(found.a, found.b)
    cell["difference"] = difference.as_dict()
    low, high = difference.low, difference.high
    largest = max(abs(x - y) for a, b in zip(found.a, found.b) for x, y in zip(a, b))
    if not comparison.robustness and largest <= SAME_NUMBERS * abs(cell["b"]):
        cell["verdict"] = NOT_REPRODUCED
        cell["why"] = f"the two sides are the same numbers, to {SAME_NUMBERS:g} of b"
    elif difference.seeds < 2:
        cell["verdict"], cell["why"] = NOT_REPRODUCED, "one seed: no interval"
    elif comparison.robustness:
        cell["margin"] = margin = ROBUSTNESS_MARGIN * cell["b"]
        cell["verdict"] = REPRODUCED if high < margin else REVERSED if low > margin else None
    else:
        paper_side = high < 0 if comparison.direction < 0 else low > 0
        other_side = low > 0 if comparison.direction < 0 else high < 0
        cell["verdict"] = REPRODUCED if paper_side else REVERSED if other_side else None
    if cell["verdict"] is None:
        cell["verdict"] = NOT_REPRODUCED
        if not comparison.robustness:
            cell["seeds_needed"] = seeds_needed(seed_means(found.a, found.b), difference)
    return cell


def claim_verdict(cells: Sequence[dict]) -> str:
    """Reproduced when every comparison with runs is; reversed when one is and none reproduced."""
    judged = [c["verdict"] for c in cells if c["verdict"] in (REPRODUCED, NOT_REPRODUCED, REVERSED)]
    if not judged:
        return RUNS_MISSING if any(c["verdict"] == RUNS_MISSING for c in cells) else NO_RECORDS
    done, back = judged.count(REPRODUCED), judged.count(REVERSED)
    verdict = (
        REPRODUCED if done == len(judged) else REVERSED if back and not done else NOT_REPRODUCED
    )
    counts = f"{done} of {len(judged)} comparisons reproduced" + (f", {back} reversed" * bool(back))
    return f"{verdict} ({counts})"


# --- the commands that make a claim's records -----------------------------------------------------

#: launch/reproduce.sh's parallax-eval options (EVAL_ARGS), for set-ups with no evaluation yet.
EVAL_OPTIONS = "--robots 16 --greedy-only --between $(LC_ALL=C seq -s ' ' -f '%.2f' 3.05 0.2 9.85)"
#: launch/reproduce.sh's parallax-eval options of the eye as trained (TRAINED_ARGS).
TRAINED_OPTIONS = "--robots 16 --split train --between"
PLAIN_PATH = re.compile(r"[\w/=,.+-]+")


def _eval_options(found: dict) -> str:
    """parallax-eval's options, read back from the evaluation the report used."""
    options = [f"--robots {int(found.get('robots', 1))}"]
    if set(found.get("mae") or {}) == {"greedy"}:
        options.append("--greedy-only")
    between = (found.get("distance_between_grid") or {}).get("per_distance", {})
    between = sorted(float(d) for d in between)
    steps = set(np.round(np.diff(between), 9))
    if len(steps) == 1:
        step = steps.pop()
        grid = f"{between[0]:.2f} {step:g} {between[-1]:.2f}"
        options.append(f"--between $(LC_ALL=C seq -s ' ' -f '%.2f' {grid})")
    elif between:
        options.append("--between " + " ".join(f"{d:.2f}" for d in between))
    return " ".join(options)


def _paths(paths_by_seed: dict[int, str]) -> str:
    """The runs' folders, as one word with a brace expansion over the seeds where they differ
    only there."""
    templates = {p.replace(f"seed={s}", "seed=@") for s, p in paths_by_seed.items()}
    plain = all(PLAIN_PATH.fullmatch(p) for p in paths_by_seed.values())
    if len(paths_by_seed) > 1 and len(templates) == 1 and plain and "@" in next(iter(templates)):
        seeds = ",".join(map(str, sorted(paths_by_seed)))
        return next(iter(templates)).replace("@", "{" + seeds + "}")
    return " ".join(shlex.quote(paths_by_seed[s]) for s in sorted(paths_by_seed))


def commands(comparison: Comparison, records: Records, prefix: str) -> list[tuple[int, str]]:
    """(order, line): `parallax-train` of both sides' runs, `parallax-eval` of those whose
    evaluations the comparison reads, then `parallax-replay` (it scores the eye's evaluations)."""
    lines, trains = [], {}
    # both sides of a comparison read the same kind of evaluation
    split = getattr(comparison.a.measure, "split", "heldout")
    evaluated = [(s, side.evaluated) for side in (comparison.a, comparison.b) for s in side.setups]
    options = (
        TRAINED_OPTIONS
        if split == "train"
        else next(
            (
                _eval_options(run.eval_for(phase))
                for setup, phase in evaluated
                if phase
                for run in records.runs(setup, prefix).values()
                if run.eval_for(phase)
            ),
            EVAL_OPTIONS,
        )
    )
    for setup, phase in evaluated:
        found = records.runs(setup, prefix)
        folder = f"{RECORDS}/{setup.folder_of(prefix)}"
        experiment = setup.experiment_of(prefix)
        if experiment is None:  # a replay: of its source's runs
            sources = {s: str(r.summary.get("replayed_from")) for s, r in found.items()}
            settings = {" ".join(r.summary.get("replay_overrides") or []) for r in found.values()}
            for setting in sorted(settings):
                lines.append((2, f"parallax-replay {_paths(sources)} --out {folder} {setting}"))
            continue
        seeds = ",".join(map(str, sorted(found))) or "0,1,2"
        trains.setdefault((folder, setup.overrides, seeds), []).append(experiment)
        if not found and setup.script:
            lines.append((0, f"{setup.script}  # trains and evaluates the runs below"))
        if phase:
            checkpoint, out = (
                ("checkpoint_before_perturbation.pt", "/eval_before")
                if phase == "before"
                else ("checkpoint.pt", "")
            )
            if split == "train":  # reproduce.sh's folders of the eye as trained
                out = "/eval_before_trained" if phase == "before" else "/eval_trained"
            paths = (
                _paths({s: relpath(r.path) for s, r in found.items()})
                if found
                else f"{folder}/*"
                + "*".join(sorted((*setup.overrides, f"experiment={experiment}")))
                + "*"
            )
            lines.append(
                (
                    1,
                    f'for RUN in {paths}; do parallax-eval "$RUN" --checkpoint {checkpoint} '
                    f'--out "$RUN{out}" {options}; done',
                )
            )
    for (folder, overrides, seeds), experiments in trains.items():
        words = (f"experiment={','.join(dict.fromkeys(experiments))}", *overrides, f"seed={seeds}")
        line = f"parallax-train -m hydra/launcher=joblib hydra.sweep.dir={folder} " + " ".join(
            words
        )
        lines.append((0, line))
    return lines


# --- the report ---------------------------------------------------------------------------------


def claims(root: str | Path = RECORDS) -> dict:
    records = Records(root)
    result = []
    for claim in CLAIMS:
        rows, cells_by_family, made_by = [], {key: [] for key in FAMILIES}, []
        for comparison in claim.comparisons:
            row = {"comparison": comparison.name, "pairs": comparison.pairs, "families": {}}
            row["paper"] = {"a_minus_b": comparison.paper, "source": comparison.paper_source}
            for key, prefix in FAMILIES.items():
                cell = judge(comparison, find(comparison, records, prefix))
                row["families"][key] = cell
                cells_by_family[key].append(cell)
                made_by += [c for c in commands(comparison, records, prefix) if c not in made_by]
            rows.append(row)
        result.append(
            {
                "number": claim.number,
                "claim": claim.title,
                "words": claim.words,
                "where": claim.where,
                "verdict": {k: claim_verdict(cells) for k, cells in cells_by_family.items()},
                "comparisons": rows,
                "commands": [line for _, line in sorted(made_by, key=lambda c: c[0])] + [COMMAND],
                "reads": claim.reads,
            }
        )
    return {"records": relpath(root), "margin": ROBUSTNESS_MARGIN, "claims": result}


def _number(value: float | None, comparison: Comparison) -> str:
    return "—" if value is None else f"{value:.{comparison.digits}f}{comparison.unit}"


def _cell_texts(cell: dict, comparison: Comparison) -> list[str]:
    if "difference" not in cell:
        return ["—", "—", "—", "0", f"{cell['verdict']} ({cell['why']})"]
    d = cell["difference"]
    digits = comparison.digits
    interval = "" if d["seeds"] < 2 else f" [{d['low']:+.{digits}f}, {d['high']:+.{digits}f}]"
    verdict = cell["verdict"]
    if cell.get("seeds_needed"):
        verdict += f" ({cell['seeds_needed']} seeds would tell)"
    if "margin" in cell:
        verdict += f" (margin +{cell['margin']:.{digits}f}{comparison.unit})"
    if cell.get("why"):
        verdict += f" ({cell['why']})"
    chosen = f" ({', '.join(cell['chosen'])})" if cell["chosen"] else ""
    return [
        _number(cell["a"], comparison),
        _number(cell["b"], comparison) + chosen,
        f"{d['mean']:+.{digits}f}{interval}",
        f"{d['seeds']} ({d['samples']} pairs)",
        verdict,
    ]


def markdown(result: dict) -> str:
    lines = [
        "# The paper's claims, each with a verdict",
        "",
        f"Made by `{COMMAND}` from the run records in `{result['records']}`; every number here is "
        "the program's. For each claim: the paper's words, the paper's own a − b where its tables "
        "print both sides, and for each family a, b and the paired difference a − b with its 95 % "
        "interval (a two-level bootstrap over seeds and, within a seed, the paired samples); "
        '"seeds" counts the seeds paired and the pairs of samples. How the verdicts are decided '
        "is at the end.",
        "",
        md_table(
            ["#", "claim", "where", FAMILY_TITLES["paper_family"], FAMILY_TITLES["ours"]],
            [
                [
                    f"[{c['number']}](#{c['number']}-{_anchor(c['claim'])})",
                    c["claim"],
                    c["where"],
                    c["verdict"]["paper_family"],
                    c["verdict"]["ours"],
                ]
                for c in result["claims"]
            ],
        ),
    ]
    for claim, data in zip(CLAIMS, result["claims"]):
        lines += ["", f"## {claim.number}. {claim.title}", "", f"> {claim.words} ({claim.where})"]
        lines += ["", claim.reads, ""]
        rows = []
        for comparison, row in zip(claim.comparisons, data["comparisons"]):
            paper = "—"
            if comparison.paper is not None:
                paper = f"{_number(comparison.paper, comparison)} ({comparison.paper_source})"
            for key in FAMILIES:
                cells = _cell_texts(row["families"][key], comparison)
                first = key == next(iter(FAMILIES))
                rows.append(
                    [comparison.name if first else "", comparison.pairs if first else ""]
                    + [paper if first else "", FAMILY_TITLES[key].split(" (")[0]]
                    + cells
                )
        header = ["comparison (a − b)", "paired on", "paper a − b", "family", "a", "b"]
        lines.append(md_table(header + ["a − b [95 %]", "seeds", "verdict"], rows))
        lines += ["", "Made by:", "", "```bash", *data["commands"], "```"]
    lines += ["", "## How the verdicts are decided", "", RULES.format(margin=result["margin"])]
    return "\n".join(lines) + "\n"


def _anchor(title: str) -> str:
    return "-".join("".join(c for c in title.lower() if c.isalnum() or c == " ").split())


def readme_lines(result: dict, doc: str = "docs/results/claims.md") -> str:
    return "\n".join(
        f"- [{c['number']}. {c['claim']}]({doc}#{c['number']}-{_anchor(c['claim'])}), "
        f"{c['where']}: paper family {c['verdict']['paper_family'].split(' (')[0]}; "
        f"ours {c['verdict']['ours'].split(' (')[0]}."
        for c in result["claims"]
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.split("\n\n")[0])
    parser.add_argument("--records", default=str(RECORDS), help="the run records' folder")
    parser.add_argument("--out", default="docs/results", help="folder for claims.md/.json")
    parser.add_argument("--readme", default=None, help="also rewrite this README's claims list")
    args = parser.parse_args(argv)
    out = Path(args.out)
    try:
        if not Path(args.records).is_dir():
            raise ReportError(f"{args.records} is not a folder of run records")
        for path in (out / "claims.md", out / "claims.json"):
            if why := file_problem(path):
                raise ReportError(f"{path}: {why}")
        if args.readme and README_BEGIN not in Path(args.readme).read_text():
            raise ReportError(f"{args.readme}: no line {README_BEGIN!r} to write after")
        result = claims(args.records)
    except (ReportError, OSError) as exc:
        print(f"claims: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        sys.exit(2)
    (out / "claims.md").write_text(markdown(result))
    (out / "claims.json").write_text(json.dumps(json_ready(result), indent=1) + "\n")
    print(f"[claims] wrote {out / 'claims.md'} and {out / 'claims.json'}")
    if args.readme:
        write_readme_table(Path(args.readme), readme_lines(result), README_BEGIN, README_END)
        print(f"[claims] wrote the claims of {args.readme}")


if __name__ == "__main__":
    main()
