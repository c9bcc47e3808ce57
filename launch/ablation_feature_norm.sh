#!/usr/bin/env bash
# Ablation — normalisation of the policy's input, the pooled activities of eq. (5): every mode
# of parallax/policy/features.py ("none" is the paper's raw input), three seeds each, on the
# default configuration (our recipe). The step sizes stay at the recipe's, so the modes whose
# features are far from unit norm ("none", "l1_per_scale") also learn with effectively smaller
# steps (docs/improvements.md §1); to compare at matched steps add e.g. policy.advantage_lr=…
# Extra arguments are Hydra overrides for every job. Report: docs/results/ablations/feature_norm.md.
# Environment settings: launch/ablation_lib.sh.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
px_ablation feature_norm "Ablation: policy feature normalisation (paper §3.4)" \
  policy.feature_norm=none,l1_per_scale,zscore,centred_unit,zscore_unit "seed=${SEEDS:-0,1,2}" "$@"
