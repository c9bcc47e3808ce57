#!/usr/bin/env bash
# The three ablations of docs/results/ablations.md, three seeds each on the default curriculum
# (5–20 cm): the scales (trained, ablation_scales.sh), the weighting y and the queue size c
# (replayed, ablation_y.sh / ablation_queue.sh). Then ablations.md: the hand-written reading
# (docs/results/ablations_notes.md) followed by each report's tables and plots
# (docs/results/ablations/*.md).
#   SCALES_ARGS   overrides of the scale runs (default: none, each family at its own budget)
#   SOURCE        runs whose eye movements the y / c ablations replay (default: the 5–20 cm
#                 weighted runs of launch/reproduce.sh, cut at their perturbation)
set -euo pipefail
here="$(dirname "${BASH_SOURCE[0]}")"
status=0
read -ra scales_args <<< "${SCALES_ARGS:-}"
PARALLAX_EVAL="${PARALLAX_EVAL:-0}" bash "$here/ablation_scales.sh" "${scales_args[@]}" || status=$?
if [[ -z "${SOURCE:-}" ]]; then
  # shellcheck disable=SC1091
  source "$here/ablation_lib.sh"
  SOURCE="$(px_runs_with "$(px_record_dir recipe)" experiment=recipe_multi_5_20_weighted | tr '\n' ' ')"
  export SOURCE="${SOURCE:-$(px_record_dir recipe)/<runs with experiment=recipe_multi_5_20_weighted>}"
fi
bash "$here/ablation_y.sh" || status=$?
bash "$here/ablation_queue.sh" || status=$?
if [[ -z "${PARALLAX_DRY_RUN:-}" ]]; then
  # shellcheck disable=SC1091
  source "$here/setup.sh"
  python - "${REPORT_ROOT:-docs/results}" <<'PY'
import re, sys
from pathlib import Path
root = Path(sys.argv[1])
parts = ["# Ablations: what each part buys", ""]
notes = root / "ablations_notes.md"
if notes.is_file():
    parts += [notes.read_text().strip(), ""]
for name in ("scales", "y", "queue"):
    report = root / "ablations" / f"{name}.md"
    if not report.is_file():
        parts += [f"## {name}: no report (the ablation did not run)", ""]
        continue
    text = report.read_text()
    title = text.splitlines()[0].lstrip("# ").strip()
    body = text.split("## Ablations", 1)[-1].split("\n## ", 1)[0]
    # the figures live beside the per-ablation reports
    body = re.sub(r"\]\(([^)/]+\.png)\)", r"](ablations/\1)", body)
    parts += [f"## {title}", "", f"Full report: [ablations/{name}.md](ablations/{name}.md).", body.strip(), ""]
(root / "ablations.md").write_text("\n".join(parts) + "\n")
print(f"[launch] wrote {root / 'ablations.md'}")
PY
fi
exit "$status"
