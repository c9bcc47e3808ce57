#!/usr/bin/env bash
# Ablation — the weighting hyper-parameter y of eq. (12), and weighting off, on the default
# curriculum (5–20 cm), three seeds. y only changes the distance learner, which never acts on the
# world, so the eye movements of one run per seed are replayed through learners with each y
# (parallax-replay: bit-identical to training that setting). Extra arguments are overrides of
# those source runs; SOURCE=GLOB replays existing runs instead (see launch/ablation_lib.sh).
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
out="$(px_sweep_dir ablation_y)"
status=0
px_distance_source "$@" || status=$?
px_replay "$out" distance.weighting=true distance.y=0.05,0.1,0.25,0.5,1,2,4 || status=$?
px_replay "$out" distance.weighting=false || status=$?
px_report "$report_root/ablations" y.md "Ablation: the weighting hyper-parameter y (paper eq. 12)" \
  ablation "$out"
exit "$status"
