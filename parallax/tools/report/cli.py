"""`parallax-report RUN_OR_MULTIRUN_DIR... [--out DIR]`: tables and figures from finished runs.

Turns run directories (written by `parallax-train`, optionally with the `eval.json` of
`parallax-eval`) into Markdown laid out like the paper's results:

- Table 2 (§4.2.2): eye-movement error of the last 100 trials per lateral position, for the
  single-position runs ("Sing.") and the multiple-position runs 5–10 and 5–20 cm;
- Table 3 (§5): the same after the perturbation (left camera rotated 15°, blur σ = 2);
- Tables 4–5 (§6): distance-estimation error per range of distances, before and after;
- figures in the manner of Figs. 7–9 (MAE curves) and Figs. 10–11 (error against distance);
- beyond the paper: held-out photographs and distances between the grid points;
- ablations: one table and one bar plot per setting that varies between the runs.

Runs that differ only by `seed` (and by settings that do not change results) form a group;
every number is a mean ± sd over the group's seeds, with n shown. A job directory with a
config but no summary is a failed or unfinished job: it is listed, never dropped silently.

The parts: runs.py (loading runs), groups.py (groups over seeds, the varying settings),
selection.py (which groups fill the paper's tables), tables.py, figures.py, build.py (the whole
report); this module is the command line.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from parallax.tools.console import footer
from parallax.tools.report.build import TABLE_CHOICES, build_report
from parallax.tools.report.runs import ReportError
from parallax.writable import folder_problem


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="parallax-report", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "paths",
        nargs="+",
        metavar="RUN_OR_MULTIRUN_DIR",
        help="run directories, or folders searched for them (e.g. outputs/multirun/…)",
    )
    parser.add_argument(
        "--out",
        default=None,
        help="folder for the Markdown, figures and JSON (default: print the Markdown only)",
    )
    parser.add_argument(
        "--name",
        default="README.md",
        help="file name of the Markdown (default README.md); "
        "other names prefix the figures and the JSON with their stem",
    )
    parser.add_argument("--title", default="parallax results", help="first heading of the report")
    parser.add_argument(
        "--tables",
        choices=TABLE_CHOICES,
        default="all",
        help="paper: Tables 2–5 and Figs. 10–11; ablation: one table per varying setting; all",
    )
    parser.add_argument(
        "--notes", default=None, help="a Markdown file put under the title (your reading)"
    )
    parser.add_argument(
        "--prefer",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="where several groups fit a cell of the paper's tables, show the one with this "
        "setting (repeatable), e.g. --prefer distance.y=0.1",
    )
    args = parser.parse_args(argv)
    try:
        problem = folder_problem(args.out) if args.out else None
        if problem:
            raise ReportError(f"--out {args.out}: {problem}; choose another folder")
        notes = None
        if args.notes:
            notes_path = Path(args.notes)
            if not notes_path.is_file():
                raise ReportError(f"--notes {args.notes}: no such file")
            notes = notes_path.read_text()
        started = time.time()
        markdown, _ = build_report(
            args.paths,
            Path(args.out) if args.out else None,
            name=args.name,
            title=args.title,
            tables=args.tables,
            notes=notes,
            prefer=args.prefer,
        )
    except ReportError as exc:
        print(f"parallax-report: error: {exc}", file=sys.stderr)
        sys.exit(2)
    print(markdown)
    if args.out:
        out = Path(args.out)
        written = sorted(p for p in out.rglob("*") if p.is_file() and p.stat().st_mtime >= started)
        footer("parallax-report", [p.relative_to(out) for p in written], out)


if __name__ == "__main__":
    main()
