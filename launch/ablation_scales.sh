#!/usr/bin/env bash
# Ablation — the sensory coder's scales (paper §3.3): coarse only, fine only, both (the
# paper's), three seeds each, on the default configuration (our recipe, 5–20 cm with weighting).
# Extra arguments are Hydra overrides for every job, e.g.
#     bash launch/ablation_scales.sh train.presentations=800
# Then parallax-eval on each run and the report docs/results/ablations/scales.md (figures and
# scales.json beside it). launch/ablation_lib.sh lists the environment settings (LAUNCHER, …).
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
px_ablation scales "Ablation: coarse and fine scales (paper §3.3)" \
  coder=coarse,fine,two_scale "seed=${SEEDS:-0,1,2}" "$@"
