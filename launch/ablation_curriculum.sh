#!/usr/bin/env bash
# Ablation — the curriculum (paper §3.2, Fig. 2): a single lateral position of 20 cm, the
# multiple positions 5–20 cm from the start (the paper), and the staged list that widens from
# 5–10 cm once the pursuit is good enough (beyond the paper), three seeds each.
# Extra arguments are Hydra overrides for every job, e.g.  bash launch/ablation_curriculum.sh train.presentations=800
# Report: docs/results/ablations/curriculum.md. Environment settings: launch/ablation_lib.sh.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
px_ablation curriculum "Ablation: curriculum (paper §3.2)" \
  curriculum=single_20,multi_5_20,staged "seed=${SEEDS:-0,1,2}" "$@"
