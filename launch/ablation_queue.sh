#!/usr/bin/env bash
# Ablation — the queue size c of eq. (9) on the default curriculum (5–20 cm), three seeds. Like
# launch/ablation_y.sh, the eye movements of one run per seed are replayed through distance
# learners with each c (parallax-replay), and each c is compared with the c the source runs were
# trained with (the paper's 300 for the paper family) on the same eye movements (paired, with
# 95 % intervals). A c larger than the presentations replayed never fills and has no distance
# error: the report shows it empty. NAME (default queue) names the reports and the replays'
# records (RECORD_ROOT/ablation_NAME, committed with their distance learner's keys only), for
# another family's SOURCE.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
name="${NAME:-queue}"
out="$(px_record_dir "ablation_$name")"
status=0
px_distance_source "$@" || status=$?
px_score_sources || status=$?
px_replay "$out" distance.queue_size=50,100,300,1000 || status=$?
px_run python -m parallax.tools.report.compact --keep distance "$out" || status=$?
px_report "$report_root/ablations" "$name.md" "Ablation: queue size c (paper eq. 9)" ablation \
  "$out" || status=$?
px_paired "$name" distance.queue_size "$(px_source_setting distance.queue_size)" "$out" \
  || status=$?
exit "$status"
