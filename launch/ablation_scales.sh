#!/usr/bin/env bash
# Ablation — the sensory coder's scales (paper §3.3): the coarse scale alone and the fine scale
# alone, each family at its own budget, three seeds each (SEEDS):
#     parallax-train experiment=paper_multi_5_10 coder=coarse|fine seed=N
#         (the paper's algorithm, 5–10 cm: its 5–20 cm runs are long)
#     parallax-train experiment=recipe_multi_5_20_weighted coder=coarse|fine seed=N   (ours)
# Both scales together are each family's own runs (launch/reproduce.sh). The runs live in
# docs/results/runs/ablation_scales (RECORD_ROOT; committed, compacted, resumable), then
# parallax-eval of each run before and after its perturbation, as the reproduction evaluates.
# Extra arguments are Hydra overrides for every run. EXPERIMENTS (comma-separated, default both
# above) picks the families' set-ups, e.g. EXPERIMENTS=recipe_multi_5_20_weighted for ours alone.
# launch/ablation_lib.sh lists the other environment settings (LAUNCHER, N_JOBS, …).
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
runs="$(px_record_dir ablation_scales)"
status=0
experiments="${EXPERIMENTS:-paper_multi_5_10,recipe_multi_5_20_weighted}"
px_sweep "$runs" "experiment=$experiments" coder=coarse,fine \
  "seed=${SEEDS:-0,1,2}" "$@" || status=$?
# as the reproduction evaluates its models (launch/reproduce.sh, EVAL_ARGS): the greedy eye on
# held-out photographs at each grid distance and between them
read -ra eval_args <<< "${EVAL_ARGS:---robots 16 --greedy-only --between $(LC_ALL=C seq -s ' ' -f '%.2f' 3.05 0.2 9.85)}"
px_eval "$runs" checkpoint.pt "" "${eval_args[@]}" || status=$?
px_eval "$runs" checkpoint_before_perturbation.pt eval_before "${eval_args[@]}" || status=$?
px_run python -m parallax.tools.report.compact "$runs" --keep replay || status=$?
px_report "$report_root/ablations" scales.md "Ablation: coarse and fine scales (paper §3.3)" \
  ablation "$runs" || status=$?
# each scale alone against both, the family's own runs of the set-up, paired by seed
for name in ${experiments//,/ }; do
  mapfile -t alone < <(px_runs_with "$runs" "experiment=$name")
  mapfile -t both < <(px_runs_with "$(px_record_dir "${name%%_*}")" "experiment=$name")
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
    alone=("$runs/<runs of $name>") both=("$(px_record_dir "${name%%_*}")/<runs of $name>")
  fi
  px_paired "scales_$name" coder.scales '["coarse", "fine"]' "${alone[@]}" "${both[@]}" \
    || status=$?
done
exit "$status"
