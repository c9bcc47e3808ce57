#!/usr/bin/env bash
# The three ablations of docs/results/ablations.md: the scales (trained at each family's budget,
# ablation_scales.sh), and the weighting y and the queue size c (replayed, ablation_y.sh /
# ablation_queue.sh) on the 5–20 cm weighted runs of each family, the paper's algorithm and our
# recipe (launch/reproduce.sh's records, cut at their perturbation). Each setting is compared
# with its baseline on the same seeds and eye movements (paired, with 95 % intervals). Then
# python -m parallax.tools.report.ablations writes ablations.md: the hand-written reading
# (docs/results/ablations_notes.md) followed by each report's tables and its paired tables.
#   SCALES_ARGS   overrides of the scale runs (default: none, each family at its own budget)
#   SOURCE        runs whose eye movements the y / c ablations replay instead of both families'
#                 (reported as y and queue)
set -euo pipefail
here="$(dirname "${BASH_SOURCE[0]}")"
status=0
read -ra scales_args <<< "${SCALES_ARGS:-}"
bash "$here/ablation_scales.sh" "${scales_args[@]}" || status=$?
# shellcheck disable=SC1091
source "$here/ablation_lib.sh"
if [[ -n "${SOURCE:-}" ]]; then
  bash "$here/ablation_y.sh" || status=$?
  bash "$here/ablation_queue.sh" || status=$?
else
  for family in paper recipe; do
    name="${family}_multi_5_20_weighted"
    SOURCE="$(px_runs_with "$(px_record_dir "$family")" "experiment=$name" | tr '\n' ' ')"
    export SOURCE="${SOURCE:-$(px_record_dir "$family")/<runs with experiment=$name>}"
    NAME="y_$family" bash "$here/ablation_y.sh" || status=$?
    NAME="queue_$family" bash "$here/ablation_queue.sh" || status=$?
  done
fi
px_run python -m parallax.tools.report.ablations "$report_root" || status=$?
exit "$status"
