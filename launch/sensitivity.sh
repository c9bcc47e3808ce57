#!/usr/bin/env bash
# The sensitivity study of the paper family (docs/paper_algorithm.md): what its numbers rest on.
# experiment=sensitivity_single_5 and sensitivity_multi_5_10 (the paper's set-ups in shorter
# runs) for every seed, with the lineage's settings and with one switch each: a file of
# conf/open_setting/ that changes the eye (+open_setting=NAME; reset_step_learnt and pan_kept on
# 5–10 cm only, as they change nothing at a single position), another of the AEC code's
# step-size sets (step_sizes=NAME) or another of the dictionary rates η those sets carry
# (dictionary_rate=NAME); the switches that change the distance learner only
# (open_setting=plain_lm and matlab_network; the family's network, without input processing and
# built anew at every fit, where the study keeps MATLAB's, and each of its two choices alone) by
# parallax-replay of the lineage's runs;
# the records compacted as committed (the lineage's keep what the replays read, the switches' what
# the table reads, the replays' their distance learner's); then the table,
# docs/results/sensitivity.md and .json. Resumable (fixed
# folders, like launch/reproduce.sh).
# Arguments with '=' are Hydra overrides for every run; the table is told of them.
#     bash launch/sensitivity.sh
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
sweep="$(px_record_dir sensitivity)"
replays="$(px_record_dir sensitivity_replays)"
setups="experiment=sensitivity_single_5,sensitivity_multi_5_10"
seeds="seed=${SEEDS:-0,1,2}"
status=0
px_sweep "$sweep" "$setups" "$seeds" "$@" || status=$?
for setting in xi_1 projection normalised_features; do
  px_sweep "$sweep" "$setups" "+open_setting=$setting" "$seeds" "$@" || status=$?
done
# the step across a pan reset learnt, the pan kept between lateral positions: both act only from
# one lateral position to the next, so at a single position their runs are the lineage's
for setting in reset_step_learnt pan_kept; do
  px_sweep "$sweep" "experiment=sensitivity_multi_5_10" "+open_setting=$setting" "$seeds" "$@" \
    || status=$?
done
for set in origin chong lukas; do
  px_sweep "$sweep" "$setups" "step_sizes=$set" "$seeds" "$@" || status=$?
done
for rate in origin lukas alex_p; do
  px_sweep "$sweep" "$setups" "dictionary_rate=$rate" "$seeds" "$@" || status=$?
done
# the lineage's runs: those launched with neither switch
lineage=()
switched=()
if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
  lineage=("$sweep/<runs of the lineage's settings>")
  switched=("$sweep/<runs with a switch>")
else
  for overrides in "$sweep"/*/.hydra/overrides.yaml; do
    [[ -f "$overrides" ]] || continue
    run="$(dirname "$(dirname "$overrides")")"
    if grep -qE -- '^- (\+open_setting|step_sizes|dictionary_rate)=' "$overrides"; then
      switched+=("$run")
    else
      lineage+=("$run")
    fi
  done
fi
if (( ${#switched[@]} )); then
  px_run python -m parallax.tools.report.compact --keep reports "${switched[@]}" || status=$?
fi
if (( ${#lineage[@]} )); then
  px_run python -m parallax.tools.report.compact --keep replay "${lineage[@]}" || status=$?
  px_run parallax-replay "${lineage[@]}" --out "$replays" \
    open_setting=plain_lm,matlab_network || status=$?
  px_run parallax-replay "${lineage[@]}" --out "$replays" distance.warm_start=false || status=$?
  px_run parallax-replay "${lineage[@]}" --out "$replays" \
    distance.input_scaling=none distance.warm_start=true,false || status=$?
  px_run python -m parallax.tools.report.compact --keep distance "$replays" || status=$?
fi
table_overrides=()
for arg in "$@"; do table_overrides+=("--override=$arg"); done
px_run python -m parallax.tools.analysis.sensitivity "$sweep" "$replays" \
  "${table_overrides[@]}" --json "$report_root/sensitivity.json" \
  --markdown "$report_root/sensitivity.md" || status=$?
exit "$status"
