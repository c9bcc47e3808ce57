#!/usr/bin/env bash
# Issue 9 ablation — the weighting hyper-parameter y of eq. (12) (paper §3.5.1; the paper gives no
# value), over a grid on the default experiment (5–20 cm), three seeds each; plus the same runs
# without weighting as the reference (Table 4's "without weighting"). A smaller y weights the
# sensitive positions (15–20 cm) more: w_k = 1/((1 + l_r − l_k)·y), lengths in cm.
# Extra arguments are Hydra overrides for every job, e.g.  bash launch/ablation_y.sh train.presentations=800
# Report: docs/results/ablations/y.md. Environment settings: launch/ablation_lib.sh.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
sweep="$(px_sweep_dir ablation_y)"
status=0
px_sweep "$sweep" distance.weighting=true distance.y=0.25,0.5,1,2,4 "seed=${SEEDS:-0,1,2}" "$@" || status=$?
px_sweep "$sweep" distance.weighting=false "seed=${SEEDS:-0,1,2}" "$@" || status=$?
px_eval "$sweep" || status=$?
px_report "$report_root/ablations" y.md "Ablation: the weighting hyper-parameter y (paper eq. 12)" \
  ablation "$sweep"
exit "$status"
