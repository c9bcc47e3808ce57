#!/usr/bin/env bash
# The render option's study (docs/performance.md, "Rendering only what the retina reads"): the
# paper family's single 5 cm and 5–10 cm set-ups with env.fovea_px=150, three seeds each (SEEDS),
# at the experiment files' own budgets, into docs/results/runs/fovea (RECORD_ROOT; committed,
# compacted, resumable); then each set-up against the family's own runs of it
# (launch/reproduce.sh's records, docs/results/runs/paper), paired by seed, with 95 % intervals
# and verdicts (python -m parallax.tools.report.paired_ablation): does rendering the fovea alone
# change the results beyond seed noise? Extra arguments are Hydra overrides for every run.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
runs="$(px_record_dir fovea)"
status=0
px_sweep "$runs" experiment=paper_single_5,paper_multi_5_10 env.fovea_px=150 \
  "seed=${SEEDS:-0,1,2}" "$@" || status=$?
px_run python -m parallax.tools.report.compact "$runs" --keep reports || status=$?
for name in paper_single_5 paper_multi_5_10; do
  mapfile -t fovea < <(px_runs_with "$runs" "experiment=$name")
  # the family's own runs: launched with their experiment and seed alone
  mapfile -t full < <(px_runs_with "$(px_record_dir paper)" "experiment=$name" \
    | while read -r run; do [[ $(wc -l < "$run/.hydra/overrides.yaml") == 2 ]] && echo "$run"; done)
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
    fovea=("$runs/<runs of $name>") full=("$(px_record_dir paper)/<runs of $name>")
  fi
  px_paired "fovea_$name" env.fovea_px null "${fovea[@]}" "${full[@]}" || status=$?
done
exit "$status"
