#!/usr/bin/env bash
# Ablation — the weighting hyper-parameter y of eq. (12), y ∈ {0.25, 0.5, 1, 2, 4}, and weighting
# off, on the default curriculum (5–20 cm), three seeds. y only changes the distance learner,
# which never acts on the world, so the eye movements of one run per seed are replayed through
# learners with each y (parallax-replay: bit-identical to training that setting), and every
# setting is compared with no weighting on the same eye movements (paired, with 95 % intervals:
# python -m parallax.tools.report.paired_ablation). Extra arguments are overrides of those source
# runs; SOURCE=GLOB replays existing runs instead (see launch/ablation_lib.sh); NAME (default y)
# names the reports and the replays' records (RECORD_ROOT/ablation_NAME, committed with their
# distance learner's keys only: their eye is their source's), for another family's SOURCE.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
name="${NAME:-y}"
out="$(px_record_dir "ablation_$name")"
status=0
px_distance_source "$@" || status=$?
px_score_sources || status=$?
px_replay "$out" distance.weighting=true distance.y=0.25,0.5,1,2,4 || status=$?
px_replay "$out" distance.weighting=false || status=$?
px_run python -m parallax.tools.report.compact --keep distance "$out" || status=$?
px_report "$report_root/ablations" "$name.md" "Ablation: the weighting hyper-parameter y (paper eq. 12)" \
  ablation "$out" || status=$?
px_paired "$name" distance.weighting,distance.y "distance.weighting=false, distance.y=1.0" \
  "$out" || status=$?
exit "$status"
