#!/usr/bin/env bash
# Shared by launch/ablation_*.sh and launch/reproduce.sh, which source it; not a script to run.
# It sets up .venv (launch/setup.sh) and provides:
#   px_sweep_dir NAME            the sweep folder of a script: $SWEEP_ROOT/NAME. It is fixed, not
#                                dated, so running a script again resumes its unfinished runs
#                                from their checkpoints (finished ones are only re-summarised).
#   px_sweep SWEEP_DIR ARGS...   parallax-train -m ARGS on the chosen launcher into SWEEP_DIR;
#                                the caller's "$@" goes last, so it overrides anything before it.
#   px_eval SWEEP_DIR [CHECKPOINT [SUBDIR [ARGS...]]]   parallax-eval every finished run whose
#                                eval.json (in RUN/SUBDIR; plain or compacted) is missing or older
#                                than its checkpoint (N_JOBS at a time; log in RUN/SUBDIR/eval.log).
#   px_needs_eval MODEL CHECKPOINT OUT   that choice, for any model (px_eval_record OUT: its record).
#   px_committed_model RUN       where the reproduction commits RUN's models.
#   px_report OUT NAME TITLE TABLES SWEEP_DIR...   parallax-report into OUT/NAME.
#   px_paired NAME FACTOR BASELINE RUNS...   every value of FACTOR against BASELINE as
#                                paired differences with 95 % intervals and verdicts
#                                (python -m parallax.tools.report.paired_ablation) into
#                                $REPORT_ROOT/ablations/NAME_paired.md and .json.
#   px_distance_source ARGS...   the finished runs whose logged eye movements the distance-learner
#                                ablations (y, c, weighting) replay, in the array distance_sources:
#                                $SOURCE if set (a glob, e.g. 'outputs/multirun/reproduce_recipe/*multi_5_20_weighted*'),
#                                else the default experiment trained for SEEDS (plus ARGS) into
#                                $SWEEP_ROOT/ablation_distance_source.
#   px_replay OUT ARGS...        parallax-replay the distance sources into OUT with distance.* ARGS
#                                (the part before any perturbation: Table 4's models), scoring
#                                again their evaluations on five photographs per distance
#                                (px_score_sources) and of the eye as trained (eval_before_trained).
#   px_score_sources             the distance ablations' scoring: each distance source's model
#                                before its perturbation (in the run, else in the committed
#                                REPORT_ROOT/checkpoints/<experiment>_seed<n>) greedy on five held-out
#                                photographs per grid distance, into SOURCE/eval_before_textures5
#                                (skipped where that eval is newer than the model).
#   px_source_setting KEY        KEY's value in the first distance source's config.yaml: the
#                                setting the source runs were trained with (a placeholder naming
#                                it where there is no such file yet, as in a dry run).
#   px_runs_with SWEEP_DIR OVERRIDE   the run folders of SWEEP_DIR launched with OVERRIDE, one per
#                                line, read from their .hydra/overrides.yaml (a long run name is
#                                shortened with a hash, so a glob on names can miss runs).
# Environment:
#   LAUNCHER=joblib        Hydra launcher: joblib (default, this machine), submitit_local, slurm,
#                          or your git-ignored local_<site> config (see conf/hydra/launcher/slurm.yaml)
#   SEEDS=0,1,2            the seeds of every setting (a sweep over seed=…)
#   N_JOBS=2               parallel jobs for joblib and for parallax-eval (default: the 2 cores)
#   SWEEP_ROOT=outputs/multirun
#   RECORD_ROOT=docs/results/runs   the reproduction's runs (px_record_dir): committed, so that the
#                          report's numbers and the runs behind them stay together (their
#                          checkpoints and TensorBoard files are ignored by git)
#   SOURCE=GLOB            runs to replay for the y / c ablations instead of training new ones
#   REPORT_ROOT=docs/results    where the reports go
#   PARALLAX_EVAL=0        skip parallax-eval (the report then uses the trainer's online errors)
#   PARALLAX_DRY_RUN=1     print the commands instead of running them (and skip the .venv set-up)
if [[ "${BASH_SOURCE[0]}" == "$0" ]]; then
  echo "launch/ablation_lib.sh is sourced by the launch scripts; run one of them instead" >&2
  exit 2
fi
if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
  # only printing: no need to create or update .venv
  cd "$(dirname "${BASH_SOURCE[0]}")/.."
else
  # shellcheck disable=SC1091
  source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
fi

# where the reports go (the scripts write into $report_root and $report_root/ablations)
report_root="${REPORT_ROOT:-docs/results}"

px_run() {
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
    printf '%q ' "$@"
    printf '\n'
  else
    "$@"
  fi
}

px_sweep_dir() {
  printf '%s/%s' "${SWEEP_ROOT:-outputs/multirun}" "$1"
}

px_record_dir() {
  printf '%s/%s' "${RECORD_ROOT:-$report_root/runs}" "$1"
}

px_sweep() {
  local sweep_dir="$1"
  shift
  local launcher="${LAUNCHER:-joblib}"
  local launcher_args=("hydra/launcher=$launcher")
  # n_jobs exists only in the joblib launcher's schema; the submitit ones would reject it
  if [[ "$launcher" == joblib ]]; then
    launcher_args+=("hydra.launcher.n_jobs=${N_JOBS:-2}")
  fi
  px_run parallax-train -m "${launcher_args[@]}" "hydra.sweep.dir=$sweep_dir" "$@"
}

px_eval() {
  # px_eval SWEEP_DIR [CHECKPOINT [SUBDIR [PARALLAX_EVAL_ARGS...]]]: parallax-eval of CHECKPOINT
  # (default checkpoint.pt) of every finished run below SWEEP_DIR into RUN/SUBDIR (default the run
  # itself) where its eval.json is missing or older than the checkpoint, N_JOBS at a time
  local sweep_dir="$1" checkpoint="${2:-checkpoint.pt}" subdir="${3:-}"
  shift $(( $# < 3 ? $# : 3 ))
  if [[ "${PARALLAX_EVAL:-1}" == 0 ]]; then
    return 0
  fi
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
    echo "parallax-eval RUN --checkpoint $checkpoint --out RUN${subdir:+/$subdir} $*  # each finished run below $sweep_dir without an up-to-date eval"
    return 0
  fi
  local todo=() summary run out failed=0
  while IFS= read -r -d '' summary; do
    run="$(dirname "$summary")"
    if px_needs_eval "$run" "$checkpoint" "$run${subdir:+/$subdir}"; then
      todo+=("$run")
    fi
  done < <(find "$sweep_dir" -name summary.json -not -path '*/.*' -print0 2>/dev/null)
  if (( ${#todo[@]} == 0 )); then
    return 0
  fi
  echo "[launch] parallax-eval of $checkpoint on ${#todo[@]} runs, ${N_JOBS:-2} at a time (logs: RUN/${subdir:+$subdir/}eval.log)"
  for run in "${todo[@]}"; do
    while (( $(jobs -rp | wc -l) >= ${N_JOBS:-2} )); do
      wait -n || failed=1
    done
    out="$run${subdir:+/$subdir}"
    mkdir -p "$out"
    {
      parallax-eval "$run" --checkpoint "$checkpoint" --out "$out" "$@" > "$out/eval.log" 2>&1 \
        || { echo "[launch] parallax-eval failed on $run (see $out/eval.log)" >&2; exit 1; }
    } &
  done
  while (( $(jobs -rp | wc -l) > 0 )); do
    wait -n || failed=1
  done
  return "$failed"
}

px_eval_record() {
  # px_eval_record OUT: prints OUT's eval.json, plain or compacted (a committed record), if any
  local file
  for file in "$1"/eval.json{,.xz,.gz}; do
    [[ -f "$file" ]] && { printf '%s\n' "$file"; return 0; }
  done
  return 1
}

px_needs_eval() {
  # px_needs_eval MODEL CHECKPOINT OUT: whether MODEL/CHECKPOINT exists and OUT holds no eval of it,
  # or (OUT inside MODEL: the run's own model) one older than it; a committed model's date is the
  # checkout's, so its evaluation is only made when missing (a compacted copy keeps the plain
  # file's modification time)
  local record
  [[ -f "$1/$2" ]] || return 1
  record="$(px_eval_record "$3")" || return 0
  [[ ( "$3" == "$1" || "$3" == "$1"/* ) && "$1/$2" -nt "$record" ]]
}

px_committed_model() {
  # px_committed_model RUN: where the reproduction commits RUN's models (config and both
  # checkpoints): $report_root/checkpoints/<experiment>_seed<n>, read from RUN's launch overrides
  # and config.yaml
  local experiment seed
  experiment="$(sed -n 's/^- experiment=//p' "$1/.hydra/overrides.yaml" 2>/dev/null)"
  seed="$(sed -n 's/^seed: //p' "$1/config.yaml" 2>/dev/null)"
  printf '%s/checkpoints/%s_seed%s' "$report_root" "${experiment:-<experiment>}" "${seed:-<seed>}"
}

px_report() {
  local out="$1" name="$2" title="$3" tables="$4"
  shift 4
  px_run parallax-report "$@" --out "$out" --name "$name" --title "$title" --tables "$tables"
}

px_paired() {
  local name="$1" factor="$2" baseline="$3" report="$report_root/ablations/$1_paired"
  shift 3
  px_run python -m parallax.tools.report.paired_ablation "$@" --factor "$factor" \
    --baseline "$baseline" --markdown "$report.md" --json "$report.json"
}

# px_ablation NAME TITLE SWEEP_ARGS...   the usual one-sweep ablation: sweep into
# $SWEEP_ROOT/ablation_NAME, evaluate, report into $REPORT_ROOT/ablations/NAME.md; returns
# non-zero if the sweep or an evaluation failed (the report is written either way).
px_ablation() {
  local name="$1" title="$2" sweep status=0
  shift 2
  sweep="$(px_sweep_dir "ablation_$name")"
  px_sweep "$sweep" "$@" || status=$?
  px_eval "$sweep" || status=$?
  px_report "$report_root/ablations" "$name.md" "$title" ablation "$sweep"
  return "$status"
}

px_distance_source() {
  if [[ -n "${SOURCE:-}" ]]; then
    # shellcheck disable=SC2206  # the glob is meant to expand
    distance_sources=( $SOURCE )
    return 0
  fi
  distance_sources=("$(px_sweep_dir ablation_distance_source)")
  px_sweep "${distance_sources[0]}" "seed=${SEEDS:-0,1,2}" "$@"
}

px_runs_with() {
  local overrides
  for overrides in "$1"/*/.hydra/overrides.yaml; do
    if [[ -f "$overrides" ]] && grep -qxF -- "- $2" "$overrides"; then
      dirname "$(dirname "$overrides")"
    fi
  done
}

px_replay() {
  local out="$1"
  shift
  px_run parallax-replay "${distance_sources[@]}" --out "$out" --until-perturbation \
    --rescore eval_before_textures5 --rescore eval_before_trained "$@"
}

px_source_setting() {
  local config="${distance_sources[0]}/config.yaml"
  if [[ -f "$config" ]]; then
    python -c 'import sys; from omegaconf import OmegaConf
print(OmegaConf.select(OmegaConf.load(sys.argv[1]), sys.argv[2], throw_on_missing=True))' \
      "$config" "$1"
  else
    printf '<%s of the source runs>' "$1"
  fi
}

px_score_sources() {
  local source summary run model status=0
  local args=(--checkpoint checkpoint_before_perturbation.pt --robots 16 --greedy-only --between none
    --textures 5)
  if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
    echo "parallax-eval MODEL ${args[*]} --out RUN/eval_before_textures5  # each finished run below ${distance_sources[*]} (MODEL: the run, or its committed checkpoints) without an up-to-date eval"
    return 0
  fi
  for source in "${distance_sources[@]}"; do
    while IFS= read -r -d '' summary; do
      run="$(dirname "$summary")" model="$run"
      if [[ ! -f "$model/checkpoint_before_perturbation.pt" ]]; then
        model="$(px_committed_model "$run")"
      fi
      if px_needs_eval "$model" checkpoint_before_perturbation.pt "$run/eval_before_textures5"; then
        parallax-eval "$model" "${args[@]}" --out "$run/eval_before_textures5" || status=$?
      elif [[ ! -f "$model/checkpoint_before_perturbation.pt" ]] \
          && ! px_eval_record "$run/eval_before_textures5" > /dev/null; then
        echo "[launch] $run: no model before its perturbation (in the run or $model), so no" \
          "scoring on five photographs per distance: train it again" >&2
        status=1
      fi
    done < <(find "$source" -name summary.json -not -path '*/.*' -print0 2>/dev/null)
  done
  return "$status"
}
