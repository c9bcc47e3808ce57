#!/usr/bin/env bash
# Reproduces the results report (docs/results/): every experiment of a family for every seed,
# parallax-eval of each multiple-position model before and after the perturbation, the 5–20 cm
# models of the recipe and the paper family (the two a user builds on) of the first headline seed
# kept in docs/results/checkpoints/<experiment>_seed<n> (committed), and the reports. A family is a
# prefix of the experiment files in conf/experiment/ (<family>_algorithm.yaml, the settings its
# files include, is not an experiment of its own):
#     bash launch/reproduce.sh              # recipe, paper, unsourced and without, then the report
#     bash launch/reproduce.sh recipe       # ours (recipe_*)
#     bash launch/reproduce.sh paper        # the paper's algorithm, its open settings from its
#                                           # lineage (paper_*)
#     bash launch/reproduce.sh unsourced    # the paper's algorithm, its open settings chosen by
#                                           # us (unsourced_*)
#     bash launch/reproduce.sh without      # the recipe less each improvement (without_*)
# Each run is `parallax-train experiment=<name> seed=<n>`; nothing is added here. An experiment
# that differs from another only in the distance learner (python -m parallax.tools.experiments)
# is not trained: parallax-replay of the other's runs gives exactly its results.
# Seeds: SEEDS (default 0,1,2); the 5–20 cm experiments of every family but without, the headline
# rows, HEADLINE_SEEDS (default 0,1,2,3,4).
# EXPERIMENTS (comma-separated names) keeps a family's steps to those experiment files, e.g.
#     EXPERIMENTS=paper_multi_5_20_weighted,paper_multi_5_20 bash launch/reproduce.sh paper
# trains, evaluates and replays only the 5–20 cm rows; the reports still read every record.
# Arguments with '=' are Hydra overrides for every run (e.g. train.presentations=20 for a
# smoke test); the others name families.
# Resumable: each family's runs live in a fixed folder, $RECORD_ROOT/<family> (default
# docs/results/runs/<family>, committed without checkpoints, TensorBoard files and figures, the
# finished runs' metrics.jsonl and eval.json compressed by python -m parallax.tools.report.compact
# before the report, which reads them so). A run with a summary.json is finished and is not trained
# again, checkpoint or not; an unfinished one continues from its checkpoint; a model is evaluated
# again only when its checkpoint is newer than its eval. Extra settings: launch/ablation_lib.sh (LAUNCHER, N_JOBS, RECORD_ROOT,
# REPORT_ROOT, PARALLAX_DRY_RUN: also the estimated wall time), plus
#   EVAL_ARGS   parallax-eval options of every model (default: the greedy eye on held-out
#               photographs, one per distance of the grid 3.0, 3.1, …, 10.0 m, and 35 distances
#               between its points)
#   WITHOUT_ARGS  the same for the without family (default: the grid only)
#   OTHER_ARGS  parallax-eval options for textures of another kind (default: the grid 3.0, 3.2,
#               …, 10.0 m, greedy only), on the 5–20 cm models of every family but without
#   BENCH_REPORT  the parallax-bench --processes report a dry run estimates the wall time from
#               (default docs/results/bench/cpu_2core.json; empty: none)
#   TRAINED_ARGS  parallax-eval options of the eye as trained, the paper's probable scoring of
#               Tables 4–5 (default: the training photographs on the grid, the learning policy
#               beside the greedy one), on the multiple-position models of every family but
#               without
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
families=() overrides=()
for arg in "$@"; do
  if [[ "$arg" == *=* ]]; then overrides+=("$arg"); else families+=("$arg"); fi
done
if (( ${#families[@]} == 0 )); then
  families=(recipe paper unsourced without)
fi
# a dry run also prints each family's wall time on this machine, estimated from the committed
# parallax-bench report (its single-robot runs side by side; parallax.tools.bench.estimate), or
# from BENCH_REPORT (empty: no estimate)
bench_report="${BENCH_REPORT-docs/results/bench/cpu_2core.json}"
if [[ -n "${PARALLAX_DRY_RUN:-}" && -n "$bench_report" && -f "$bench_report" ]]; then
  for family in "${families[@]}"; do
    python -m parallax.tools.bench.estimate "$bench_report" "$family" \
      --seeds "$(tr ',' '\n' <<< "${SEEDS:-0,1,2}" | wc -l)" \
      --headline-seeds "$(tr ',' '\n' <<< "${HEADLINE_SEEDS:-0,1,2,3,4}" | wc -l)" || true
  done
fi
read -ra eval_args <<< "${EVAL_ARGS:---robots 16 --greedy-only --between $(LC_ALL=C seq -s ' ' -f '%.2f' 3.05 0.2 9.85)}"
# the recipe less an improvement: the grid alone
read -ra without_args <<< "${WITHOUT_ARGS:---robots 16 --greedy-only --between}"
read -ra other_args <<< "${OTHER_ARGS:---robots 16 --greedy-only --between --distances $(LC_ALL=C seq -s ' ' -f '%.1f' 3.0 0.2 10.0)}"
read -ra trained_args <<< "${TRAINED_ARGS:---robots 16 --split train --between}"
# textures of another kind than the photographs: generated ones, and a folder of photographs of
# other subjects that neither split uses (matplotlib's and scikit-image's sample images)
other_folder="$(px_sweep_dir stimuli_other)"  # copies of installed files: not committed
if [[ -z "${PARALLAX_DRY_RUN:-}" && ! -d "$other_folder" ]]; then
  mkdir -p "$other_folder"
  python - "$other_folder" <<'EOF'
import shutil, sys
from pathlib import Path
import matplotlib, skimage
mpl, ski = Path(matplotlib.get_data_path()) / "sample_data", Path(skimage.__file__).parent / "data"
for path in (mpl / "grace_hopper.jpg", mpl / "Minduka_Present_Blue_Pack.png",
             ski / "clock_motion.png", ski / "hubble_deep_field.jpg", ski / "microaneurysms.png"):
    shutil.copy(path, sys.argv[1])
EOF
fi
other_kinds=(
  "procedural:env.stimuli.source=procedural env.stimuli.kind=dead_leaves"
  "other_photos:env.stimuli.dir=$other_folder env.stimuli.count=null"
)

status=0
evals=()  # one parallax-eval command line each, run N_JOBS at a time
queue_eval() {  # MODEL CHECKPOINT OUT ARGS...: queue an eval unless OUT/eval.json is up to date;
  # ARGS may start with env.stimuli.KEY=VALUE settings, which go right after MODEL
  local model="$1" ckpt="$2" out="$3" settings=()
  shift 3
  while (( $# )) && [[ "$1" == env.stimuli.* ]]; do settings+=("$1"); shift; done
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]] || px_needs_eval "$model" "$ckpt" "$out"; then
    evals+=("$(printf '%q ' parallax-eval "$model" "${settings[@]}" --checkpoint "$ckpt" --out "$out" "$@")")
    eval_logs+=("$out/eval.log")
  fi
}
eval_logs=()

unrecorded_seeds() {  # SWEEP NAME SEEDS: those of the comma-separated SEEDS with no finished run
  local sweep="$1" name="$2" seed want run missing=() found
  IFS=, read -ra seeds <<< "$3"
  for seed in "${seeds[@]}"; do
    # a finished run: a summary.json beside exactly these overrides (the run folder's name may
    # be shortened with a hash, so the overrides are read, not the name)
    want="$(printf '%s\n' "experiment=$name" "seed=$seed" "${overrides[@]}" | sort)"
    found=0
    while IFS= read -r run; do
      [[ -f "$run/summary.json" ]] || continue
      if [[ "$(sed -n 's/^- //p' "$run/.hydra/overrides.yaml" | sort)" == "$want" ]]; then found=1; break; fi
    done < <(px_runs_with "$sweep" "experiment=$name")
    (( found )) || missing+=("$seed")
  done
  (IFS=,; echo "${missing[*]}")
}

train_unrecorded() {  # SWEEP SEEDS NAME...: one sweep per set of seeds that still lack a run
  local sweep="$1" seeds="$2" name missing
  shift 2
  local -A names_by_seeds=()
  for name in "$@"; do
    missing="$(unrecorded_seeds "$sweep" "$name" "$seeds")"
    [[ -n "$missing" ]] && names_by_seeds[$missing]+="${names_by_seeds[$missing]:+,}$name"
  done
  while IFS= read -r missing; do
    [[ -n "$missing" ]] || continue
    px_sweep "$sweep" "experiment=${names_by_seeds[$missing]}" "seed=$missing" "${overrides[@]}" \
      || status=$?
  done < <(printf '%s\n' "${!names_by_seeds[@]}" | sort)
}

keep_models() {  # SWEEP NAME...: the models of the first headline seed's finished runs, committed
  # beside the records so that anyone can run parallax-eval or parallax-render on them (every
  # run's evaluations are committed; the other seeds' models are not, to keep the repository light)
  local sweep="$1" name run keep first="${HEADLINE_SEEDS:-0,1,2,3,4}"
  shift
  first="${first%%,*}"
  for name in "$@"; do
    while IFS= read -r run; do
      [[ -f "$run/summary.json" && -f "$run/checkpoint.pt" ]] || continue
      [[ "$(sed -n 's/^seed: //p' "$run/config.yaml")" == "$first" ]] || continue
      keep="$(px_committed_model "$run")"
      px_run mkdir -p "$keep"
      px_run cp "$run/config.yaml" "$run/checkpoint.pt" "$run/checkpoint_before_perturbation.pt" "$keep/"
    done < <(px_runs_with "$sweep" "experiment=$name")
  done
}

run_evals() {
  (( ${#evals[@]} )) || return 0
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
    printf '%s\n' "${evals[@]}"
  else
    echo "[reproduce] ${#evals[@]} evaluations, ${N_JOBS:-2} at a time (logs: OUT/eval.log)"
    local k jobs=()
    for k in "${!evals[@]}"; do
      jobs+=("mkdir -p $(printf '%q' "$(dirname "${eval_logs[$k]}")") && ${evals[$k]}> $(printf '%q' "${eval_logs[$k]}") 2>&1")
    done
    # shellcheck disable=SC2016
    printf '%s\0' "${jobs[@]}" | xargs -0 -n 1 -P "${N_JOBS:-2}" sh -c \
      'sh -c "$1" || { echo "[reproduce] failed: $1" >&2; exit 1; }' sh || status=1
  fi
  evals=() eval_logs=()
}

evaluate() {  # SWEEP NAME...: the evaluations of those experiments' finished models
  local sweep="$1" name run runs args kind settings model
  shift
  # every multiple-position model, before and after the perturbation (Tables 4–5)
  for name in "$@"; do
    [[ "$name" == *single* ]] && continue
    runs=()
    mapfile -t runs < <(px_runs_with "$sweep" "experiment=$name")
    [[ -n "${PARALLAX_DRY_RUN:-}" ]] && runs=("$sweep/<runs of $name>")
    for run in "${runs[@]}"; do
      [[ -n "${PARALLAX_DRY_RUN:-}" || -f "$run/summary.json" ]] || continue
      if [[ "$family" == without ]]; then args=("${without_args[@]}"); else args=("${eval_args[@]}"); fi
      model="$run"
      if [[ -z "${PARALLAX_DRY_RUN:-}" && ! -f "$run/checkpoint.pt" ]]; then
        # a committed record: a headline model is kept in docs/results/checkpoints
        model="$(px_committed_model "$run")"
      fi
      queue_eval "$model" checkpoint.pt "$run" "${args[@]}"
      queue_eval "$model" checkpoint_before_perturbation.pt "$run/eval_before" "${args[@]}"
      if [[ "$family" != without ]]; then
        queue_eval "$model" checkpoint.pt "$run/eval_trained" "${trained_args[@]}"
        queue_eval "$model" checkpoint_before_perturbation.pt "$run/eval_before_trained" \
          "${trained_args[@]}"
      fi
      if [[ "$family" != without && "$name" == *multi_5_20* ]]; then
        for kind in "${other_kinds[@]}"; do
          read -ra settings <<< "${kind#*:}"
          queue_eval "$model" checkpoint.pt "$run/eval_${kind%%:*}" "${settings[@]}" "${other_args[@]}"
          queue_eval "$model" checkpoint_before_perturbation.pt "$run/eval_before_${kind%%:*}" \
            "${settings[@]}" "${other_args[@]}"
        done
      fi
    done
  done
  run_evals
}

for family in "${families[@]}"; do
  names=()
  for file in conf/experiment/"${family}"_*.yaml; do
    name="$(basename "$file" .yaml)"
    # <family>_algorithm.yaml holds the settings that the family's <setup> files include
    [[ "$name" == *_algorithm || ! -f "$file" ]] || names+=("$name")
  done
  if [[ -n "${EXPERIMENTS:-}" ]]; then
    kept=()
    for name in "${names[@]}"; do [[ ",$EXPERIMENTS," == *",$name,"* ]] && kept+=("$name"); done
    names=("${kept[@]}")
  fi
  if (( ${#names[@]} == 0 )); then
    echo "launch/reproduce.sh: no experiment files conf/experiment/${family}_*.yaml${EXPERIMENTS:+ among EXPERIMENTS=$EXPERIMENTS}" >&2
    exit 2
  fi
  # reverse order: the 5–20 cm weighted file, the headline, comes before the rows replayed from it
  mapfile -t names < <(printf '%s\n' "${names[@]}" | sort -r)
  candidates=("${names[@]}")
  # the recipe less an improvement on the distance side replays the recipe's own runs
  [[ "$family" == without ]] && candidates=(recipe_multi_5_20_weighted "${names[@]}")
  plan_text="$(python -m parallax.tools.experiments "${candidates[@]}")" || exit 2
  mapfile -t plan <<< "$plan_text"
  sweep="$(px_record_dir "$family")"
  replays="$(px_record_dir "${family}_replays")"
  headline=() others=()
  for line in "${plan[@]}"; do
    read -r action name _ <<< "$line"
    [[ "$action" == train && " ${names[*]} " == *" $name "* ]] || continue
    if [[ "$family" != without && "$name" == *multi_5_20* ]]; then headline+=("$name"); else others+=("$name"); fi
  done
  # the headline models first, kept and evaluated before the other files are trained
  train_unrecorded "$sweep" "${HEADLINE_SEEDS:-0,1,2,3,4}" "${headline[@]}"
  [[ "$family" == recipe || "$family" == paper ]] && keep_models "$sweep" "${headline[@]}"
  evaluate "$sweep" "${headline[@]}"
  train_unrecorded "$sweep" "${SEEDS:-0,1,2}" "${others[@]}"
  evaluate "$sweep" "${others[@]}"

  # the experiments that differ only in the distance learner, from their source's runs
  for line in "${plan[@]}"; do
    read -r action name source settings <<< "$line"
    [[ "$action" == replay && " ${names[*]} " == *" $name "* ]] || continue
    source_sweep="$(px_record_dir "${source%%_*}")"
    mapfile -t runs < <(px_runs_with "$source_sweep" "experiment=$source")
    [[ -n "${PARALLAX_DRY_RUN:-}" ]] && runs=("$source_sweep/<runs of $source>")
    finished=()
    for run in "${runs[@]}"; do
      [[ -n "${PARALLAX_DRY_RUN:-}" || -f "$run/summary.json" ]] && finished+=("$run")
    done
    (( ${#finished[@]} )) || continue
    # shellcheck disable=SC2086  # the overrides are words
    px_run parallax-replay "${finished[@]}" --out "$replays/$name" $settings || status=$?
  done

  # each family's own report: docs/results/<family>.md; the reading of the results, written by
  # hand, is kept across re-runs in notes_<family>.md
  notes=()
  if [[ -f "$report_root/notes_$family.md" ]]; then
    notes=(--notes "$report_root/notes_$family.md")
  fi
  sources=("$sweep")
  [[ -d "$replays" || -n "${PARALLAX_DRY_RUN:-}" ]] && sources+=("$replays")
  if [[ -z "${PARALLAX_DRY_RUN:-}" ]] && ! compgen -G "$sweep/*/summary.json" > /dev/null; then
    echo "[reproduce] no finished runs in $sweep: no report for $family" >&2
    status=1
    continue
  fi
  # the records as they are committed: the finished runs' metrics.jsonl and eval.json compressed,
  # keeping what parallax-replay and the reports read; the single positions' (which nothing
  # replays) only what the reports read; the replays' only their distance learner's (their eye
  # is their source's)
  px_run python -m parallax.tools.report.compact --keep replay "$sweep" || status=$?
  if [[ -d "$replays" || -n "${PARALLAX_DRY_RUN:-}" ]]; then
    px_run python -m parallax.tools.report.compact --keep distance "$replays" || status=$?
  fi
  singles=("$sweep"/*single_*)
  if [[ -e "${singles[0]}" ]]; then
    px_run python -m parallax.tools.report.compact --keep reports "${singles[@]}" || status=$?
  fi
  # Tables 4–5's runs whose records predate the network's score on its own queue get it from a
  # replay as trained (a run trained now writes it itself; those are left alone)
  multis=("$sweep"/*multi_*)
  if [[ -e "${multis[0]}" || -n "${PARALLAX_DRY_RUN:-}" ]]; then
    px_run python -m parallax.tools.report.queue_scores "${multis[@]}" || status=$?
  fi
  if [[ "$family" == without ]]; then
    px_run python -m parallax.tools.report.leave_one_out "${sources[@]}" \
      "$(px_record_dir recipe)" --out "$report_root" "${notes[@]}" || status=$?
  else
    px_report "$report_root" "$family.md" "Tables 2–5 and Figs. 7–11 ($family)" paper \
      "${sources[@]}" "${notes[@]}" || status=$?
  fi
done

# the eye's share of the recipe's 5–20 cm distance error, which notes.md reads (eye_bound.json)
mapfile -t headline_runs < <(px_runs_with "$(px_record_dir recipe)" experiment=recipe_multi_5_20_weighted)
eval_dirs=()
for run in "${headline_runs[@]}"; do
  px_eval_record "$run/eval_before" > /dev/null && eval_dirs+=("$run/eval_before")
done
for run in "${headline_runs[@]}"; do
  px_eval_record "$run" > /dev/null && eval_dirs+=("$run")
done
if (( ${#eval_dirs[@]} )); then
  px_run python -m parallax.tools.analysis.eye_bound "${eval_dirs[@]}" \
    --json "$report_root/eye_bound.json" || status=$?
fi

# the three columns: the paper's numbers, the paper's algorithm (the paper family, its open
# settings from its lineage, once reported; else the unsourced family, those settings ours), ours
middle=unsourced
if [[ -f "$report_root/paper.json" ]] || [[ -n "${PARALLAX_DRY_RUN:-}" && " ${families[*]} " == *" paper "* ]]; then
  middle=paper
fi
if [[ -f "$report_root/$middle.json" && -f "$report_root/recipe.json" ]] || [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
  notes=()
  [[ -f "$report_root/notes.md" ]] && notes=(--notes "$report_root/notes.md")
  px_run python -m parallax.tools.report.compare "$report_root/$middle.json" \
    "$report_root/recipe.json" --middle "$middle" --out "$report_root" --readme README.md \
    "${notes[@]}" || status=$?
fi

# the paper's claims, each with a verdict, from the same records (docs/results/claims.md and the
# README's list; the scales claim reads the runs of launch/ablation_scales.sh when they are there)
px_run python -m parallax.tools.report.claims --records "${RECORD_ROOT:-$report_root/runs}" \
  --out "$report_root" --readme README.md || status=$?
exit "$status"
