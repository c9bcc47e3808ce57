#!/usr/bin/env bash
# Ablation — the pan at each new lateral position: reset to 0 (the paper) or kept from the
# previous position, three seeds each, on the default configuration (our recipe, 5–20 cm with
# weighting).
# Extra arguments are Hydra overrides for every job. Report: docs/results/ablations/pan_reset.md.
# Environment settings: launch/ablation_lib.sh.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
px_ablation pan_reset "Ablation: pan reset between lateral positions" \
  env.pan_reset=true,false "seed=${SEEDS:-0,1,2}" "$@"
