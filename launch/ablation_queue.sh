#!/usr/bin/env bash
# Issue 9 ablation — the queue size c of eq. (9) (paper §3.5; the paper uses 300): c ∈ {50, 100,
# 300, 1000}, three seeds each, on the default experiment (5–20 cm with weighting).
# The distance learner starts only once its queue is full, i.e. after c presentations: give the
# runs train.presentations well above 1000 or the c = 1000 row has no distance error at all
# (the report shows "—" there rather than hiding it).
# Extra arguments are Hydra overrides for every job, e.g.  bash launch/ablation_queue.sh train.presentations=2000
# Report: docs/results/ablations/queue.md. Environment settings: launch/ablation_lib.sh.
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
px_ablation queue "Ablation: queue size c (paper eq. 9)" \
  distance.queue_size=50,100,300,1000 "seed=${SEEDS:-0,1,2}" "$@"
