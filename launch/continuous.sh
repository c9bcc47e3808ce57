#!/usr/bin/env bash
# The continuous sweep (docs/continuous.md): the body sweeps 5–20 cm while the eye pursues.
#   1. experiment=continuous_multi_5_20_weighted for every seed (SEEDS, default 0,1,2);
#   2. the same with coder.pairing=consecutive (seed 0): which pairing learns to pursue;
#   3. the speed curve (seed 0): env.sweep.speed_m up to the fastest the eye can follow at
#      3 m, each run about 64,640 iterations long (train.presentations = 64,640 / T);
#   4. parallax-eval of every model on the held-out photographs, as the recipe's are evaluated;
#   5. the records compacted (keeping what replays read; the speed runs' only what the report
#      reads), and the report, docs/results/continuous.md and .json (python -m
#      parallax.tools.report.continuous), beside the recipe's pick-and-place 5–20 cm runs.
# Resumable (fixed folders, like launch/reproduce.sh). Arguments with '=' are Hydra overrides
# for every run.
#     bash launch/continuous.sh
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
runs="$(px_record_dir continuous)"
pairing="$(px_record_dir continuous_pairing)"
speeds="$(px_record_dir continuous_speed)"
experiment="experiment=continuous_multi_5_20_weighted"
status=0
px_sweep "$runs" "$experiment" "seed=${SEEDS:-0,1,2}" "$@" || status=$?
px_run parallax-train "$experiment" seed=0 coder.pairing=consecutive \
  "hydra.run.dir='$pairing/consecutive_seed0'" "$@" || status=$?
# SPEED:PRESENTATIONS, T = ⌈0.2 m / speed⌉ + 1 iterations a presentation (0.002 is step 1's)
for pair in 0.001:322 0.004:1267 0.007:2155 0.0104:3078; do
  speed=${pair%:*} presentations=${pair#*:}
  px_run parallax-train "$experiment" seed=0 "env.sweep.speed_m=$speed" \
    "train.presentations=$presentations" "hydra.run.dir='$speeds/speed_m=$speed,seed=0'" "$@" ||
    status=$?
done
read -ra eval_args <<< "${EVAL_ARGS:---robots 16 --greedy-only --between $(LC_ALL=C seq -s ' ' -f '%.2f' 3.05 0.2 9.85)}"
# every finished run without an eval.json (plain, or compressed when committed)
while IFS= read -r -d '' summary; do
  run="$(dirname "$summary")"
  if [[ -f "$run/checkpoint.pt" && ! -f "$run/eval.json" && ! -f "$run/eval.json.xz" ]]; then
    px_run parallax-eval "$run" "${eval_args[@]}" || status=$?
  fi
done < <(find "$runs" "$pairing" "$speeds" -name summary.json -not -path '*/.*' -print0 2>/dev/null)
# the records as they are committed, keeping what parallax-replay and the report read; the speed
# runs', which nothing replays, only what the report reads
px_run python -m parallax.tools.report.compact --keep replay "$runs" "$pairing" || status=$?
px_run python -m parallax.tools.report.compact --keep reports "$speeds" || status=$?
px_run python -m parallax.tools.report.continuous "$runs" --pairing "$pairing" \
  --speeds "$speeds" --recipe "$(px_record_dir recipe)" \
  --recipe-last "$(px_record_dir without_replays)/without_best_readout" \
  --json "$report_root/continuous.json" --markdown "$report_root/continuous.md" || status=$?
exit "$status"
