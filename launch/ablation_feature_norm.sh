#!/usr/bin/env bash
# Issue 9 ablation — normalisation of the policy's input, the pooled activities of eq. (5):
# every mode of parallax/policy/features.py ("none" is the paper's raw input), three seeds each,
# on the default experiment. The step sizes stay at the shipped ones, so the modes whose features
# are far from unit norm ("none", "l1_per_scale") also learn with effectively smaller steps
# (parallax/policy/TUNING.md); to compare at matched steps add e.g. policy.advantage_lr=…
# Extra arguments are Hydra overrides for every job. Report: docs/results/ablations/feature_norm.md.
# Environment settings: launch/ablation_lib.sh.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
sweep="$(px_sweep_dir ablation_feature_norm)"
status=0
modes=none,l1_per_scale,zscore,centred_unit,zscore_unit
px_sweep "$sweep" "policy.feature_norm=$modes" "seed=${SEEDS:-0,1,2}" "$@" || status=$?
px_eval "$sweep" || status=$?
px_report "$report_root/ablations" feature_norm.md "Ablation: policy feature normalisation (paper §3.4)" ablation \
  "$sweep"
exit "$status"
