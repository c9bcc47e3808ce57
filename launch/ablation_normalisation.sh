#!/usr/bin/env bash
# Ablation — patch normalisation in the sensory coder (paper §3.3): each eye's half of a
# binocular patch normalised on its own (per_half) or the 200-vector as a whole (joint), three
# seeds each, on the default configuration (our recipe, 5–20 cm with weighting).
# Extra arguments are Hydra overrides for every job. Report: docs/results/ablations/normalisation.md.
# Environment settings: launch/ablation_lib.sh.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
px_ablation normalisation "Ablation: patch normalisation (paper §3.3)" \
  coder.normalisation=per_half,joint "seed=${SEEDS:-0,1,2}" "$@"
