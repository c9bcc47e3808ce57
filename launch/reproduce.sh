#!/usr/bin/env bash
# Issue 8 — the paper's experiments (§4.2, §5, §6), three seeds each (the paper's three
# simulations): single lateral positions 5, 7, 10, 13, 15, 20 cm; multiple positions 5–10 and
# 5–20 cm without weighting; 5–20 cm with weighting. Each run's second half is §5's robustness
# test (left camera rotated 15°, blur σ = 2, training continuing) — conf/experiment/paper_*.yaml.
# Extra arguments are Hydra overrides for every job; size the budget here, e.g.
#     bash launch/reproduce.sh train.presentations=2000
# Then parallax-eval on each run (held-out textures, distances between the grid points) and
# the report docs/results/README.md with Tables 2–5 and Figs. 7–11 (results.json beside it).
# Environment settings: launch/ablation_lib.sh (LAUNCHER, N_JOBS, PARALLAX_EVAL, …).
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
sweep="$(px_sweep_dir reproduce)"
experiments=paper_single_5,paper_single_7,paper_single_10,paper_single_13,paper_single_15,paper_single_20
experiments+=,paper_multi_5_10,paper_multi_5_20,paper_multi_5_20_weighted
status=0
px_sweep "$sweep" "experiment=$experiments" "seed=${SEEDS:-0,1,2}" "$@" || status=$?
px_eval "$sweep" || status=$?
notes=()
if [[ -f "$report_root/notes.md" ]]; then
  # the reading of the results, written by hand and kept across re-runs
  notes=(--notes "$report_root/notes.md")
fi
px_report "$report_root" README.md "Reproducing the paper: Tables 2–5 and Figs. 7–11" paper \
  "$sweep" "${notes[@]}"
exit "$status"
