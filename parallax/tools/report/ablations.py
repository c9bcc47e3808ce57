"""`python -m parallax.tools.report.ablations [ROOT]`: ROOT/ablations.md (default docs/results),
the ablations of the coder's scales (§3.3), the weighting's y (eq. 12) and the queue size c
(eq. 9), assembled from what `launch/ablations.sh` wrote: the hand-written reading
(ROOT/ablations_notes.md), then each ablation's report (parallax-report, ROOT/ablations/NAME.md)
and its paired differences against the baseline with their intervals and verdicts
(parallax.tools.report.paired_ablation, ROOT/ablations/*_paired.md).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

#: Each ablation's report and its paired tables, in the order of ablations.md: the scales on
#: each family's set-up, y and c on each family's 5–20 cm runs.
ABLATIONS = (
    ("scales", ("scales_paper_multi_5_10", "scales_recipe_multi_5_20_weighted")),
    ("y_paper", ("y_paper",)),
    ("y_recipe", ("y_recipe",)),
    ("queue_paper", ("queue_paper",)),
    ("queue_recipe", ("queue_recipe",)),
)


def section(folder: Path, name: str, paired: tuple[str, ...]) -> list[str]:
    """One ablation's part of ablations.md: its report's tables (the figures' links made relative
    to ROOT) and its paired tables; a line saying so where it did not run."""
    report = folder / f"{name}.md"
    if not report.is_file():
        return [f"## {name}: no report (the ablation did not run)", ""]
    text = report.read_text()
    title = text.splitlines()[0].lstrip("# ").strip()
    body = text.split("## Ablations", 1)[-1].split("\n## ", 1)[0]
    # the figures live beside the per-ablation reports
    body = re.sub(r"\]\(([^)/]+\.png)\)", r"](ablations/\1)", body)
    lines = [f"## {title}", "", f"Full report: [ablations/{name}.md](ablations/{name}.md).", ""]
    lines += [body.strip(), ""]
    for table in paired:
        path = folder / f"{table}_paired.md"
        if path.is_file():
            lines += [f"Paired ({table}): " + path.read_text().strip(), ""]
        else:
            lines += [f"Paired ({table}): not made (its runs are missing).", ""]
    return lines


def assemble(root: Path) -> str:
    parts = ["# Ablations: what each part buys", ""]
    notes = root / "ablations_notes.md"
    if notes.is_file():
        parts += [notes.read_text().strip(), ""]
    for name, paired in ABLATIONS:
        parts += section(root / "ablations", name, paired)
    return "\n".join(parts).rstrip() + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.ablations", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("root", nargs="?", default="docs/results", type=Path)
    args = parser.parse_args(argv)
    if not args.root.is_dir():
        print(f"ablations: error: {args.root} is not a folder", file=sys.stderr)
        sys.exit(2)
    out = args.root / "ablations.md"
    out.write_text(assemble(args.root))
    print(f"[ablations] wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    main()
