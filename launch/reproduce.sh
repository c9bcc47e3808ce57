#!/usr/bin/env bash
# Reproduces the results report (docs/results/README.md): every experiment of a family for every
# seed, parallax-eval of each finished multiple-position run before and after the perturbation,
# the committed checkpoints, and the report. A family is a prefix of the experiment files in
# conf/experiment/:
#     bash launch/reproduce.sh              # recipe: ours (recipe_*.yaml)
#     bash launch/reproduce.sh paper        # the paper's algorithm as written (paper_*.yaml)
#     bash launch/reproduce.sh recipe paper # both
# Each run is `parallax-train experiment=<family>_<setup> seed=<n>`; nothing is added here.
# Arguments with '=' are Hydra overrides for every run (e.g. train.presentations=20 for a
# smoke test); the others name families.
# Resumable: each family's runs live in a fixed folder ($SWEEP_ROOT/reproduce_<family>) and
# continue from their checkpoints. Extra settings: launch/ablation_lib.sh (LAUNCHER, N_JOBS,
# SEEDS, SWEEP_ROOT, REPORT_ROOT, PARALLAX_DRY_RUN), plus
#   EVAL_ARGS   parallax-eval options (default: the grid 3.0, 3.5, …, 10.0 m, three held-out
#               photographs per distance)
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
families=() overrides=()
for arg in "$@"; do
  if [[ "$arg" == *=* ]]; then overrides+=("$arg"); else families+=("$arg"); fi
done
if (( ${#families[@]} == 0 )); then
  families=(recipe)
fi
read -ra eval_args <<< "${EVAL_ARGS:---distances 3.0 3.5 4.0 4.5 5.0 5.5 6.0 6.5 7.0 7.5 8.0 8.5 9.0 9.5 10.0 --textures 3}"
status=0
for family in "${families[@]}"; do
  names=()
  for file in conf/experiment/"${family}"_*.yaml; do
    name="$(basename "$file" .yaml)"
    # paper_algorithm.yaml holds the paper's settings that the paper_<setup> files include
    [[ "$name" == paper_algorithm ]] || names+=("$name")
  done
  if (( ${#names[@]} == 0 )); then
    echo "launch/reproduce.sh: no experiment files conf/experiment/${family}_*.yaml" >&2
    exit 2
  fi
  sweep="$(px_sweep_dir "reproduce_$family")"
  px_sweep "$sweep" "experiment=$(IFS=,; echo "${names[*]}")" "seed=${SEEDS:-0,1,2}" \
    "${overrides[@]}" || status=$?

  runs=()
  for name in "${names[@]}"; do
    [[ "$name" == *multi* ]] && mapfile -t -O "${#runs[@]}" runs < <(px_runs_with "$sweep" "experiment=$name")
  done
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
    runs=("$sweep/<runs of the ${family}_multi_* experiments>")
  fi
  for run in "${runs[@]}"; do
    # finished runs whose evaluation is missing or older than the checkpoint
    if [[ -n "${PARALLAX_DRY_RUN:-}" || ( -f "$run/summary.json" && ! "$run/eval.json" -nt "$run/checkpoint.pt" ) ]]; then
      px_run parallax-eval "$run" "${eval_args[@]}" || status=$?
      px_run parallax-eval "$run" "${eval_args[@]}" --checkpoint checkpoint_before_perturbation.pt \
        --out "$run/eval_before" || status=$?
    fi
  done

  if [[ "$family" == recipe ]]; then
    # the recipe's 5–20 cm weighted models, before and after the perturbation, so that anyone can
    # run parallax-eval on them without training: a run directory of its own per seed
    mapfile -t weighted < <(px_runs_with "$sweep" experiment=recipe_multi_5_20_weighted)
    for run in "${weighted[@]}"; do
      seed="$(sed -n 's/^seed: //p' "$run/config.yaml" 2>/dev/null || true)"
      if [[ -f "$run/summary.json" ]]; then
        keep="$report_root/checkpoints/multi_5_20_weighted_seed${seed:-N}"
        px_run mkdir -p "$keep"
        px_run cp "$run/config.yaml" "$run/checkpoint.pt" "$run/checkpoint_before_perturbation.pt" "$keep/"
      fi
    done
  fi

  # the recipe's report is docs/results/README.md, the paper-as-written one paper.md; the
  # reading of the results, written by hand, is kept across re-runs in notes(_paper).md
  if [[ "$family" == recipe ]]; then report=README.md notes_file=notes.md; else report="$family.md" notes_file="notes_$family.md"; fi
  notes=()
  if [[ -f "$report_root/$notes_file" ]]; then
    notes=(--notes "$report_root/$notes_file")
  fi
  px_report "$report_root" "$report" "Tables 2–5 and Figs. 7–11 ($family)" paper "$sweep" \
    "${notes[@]}" || status=$?
done
exit "$status"
