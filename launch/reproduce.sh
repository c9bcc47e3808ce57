#!/usr/bin/env bash
# Issue 8 — the paper's experiments (§4.2, §5, §6), three seeds each (the paper's three
# simulations), with the budgets of the committed report docs/results/README.md (a 2-core CPU,
# about 2 hours with both cores busy):
#   single lateral positions 5, 7, 10, 13, 15, 20 cm     400 presentations (12 000 iterations)
#   multiple positions 5–10 cm                            300 presentations (54 000 iterations)
#   multiple positions 5–20 cm with weighting             400 presentations (192 000 iterations),
#                                                         queue c = 100, y = 1 (see below)
# The single and 5–10 cm runs have §5's robustness test (left camera rotated 15°, blur σ = 2,
# training continuing) in their second half, as in conf/perturbation/rotate_blur.yaml; the
# 5–20 cm runs from presentation 133 on (start fraction 0.3325 of 400), so that 133 presentations
# come before it, as in the session-9 report, and 267 after it (session 10 lengthened the
# continuation: 67 presentations after it left Table 5 short). "5–20 cm without weighting" (Tables 4–5) replays the weighted runs'
# eye movements through a learner without weighting (parallax-replay; the distance learner
# never acts on the world, so this is exactly what training it would give).
# Then parallax-eval of the 5–10 and 5–20 cm models before and after the perturbation (held-out
# textures, distances between the grid points), their checkpoints copied into
# docs/results/checkpoints/, and the report (results.json beside it).
# Since session 5 every run also uses settings beyond the paper, chosen on probes
# (docs/results/beyond_the_paper.md): the policy's state relative to the zero-disparity view,
# trials starting from a random pan in ±2°, weight decay 0.1 in the LM fit, and (session 6) the
# eye's own pan as one more policy feature; (session 9) the last step's signed change of reward
# as one more policy feature, with gain 10 (30 in the single-position runs since session 10:
# SINGLE_IMPROVEMENTS); (session 11) the distance learner reads each trial's pan where the
# coder's reward peaked instead of its last pan (train.distance_readout=best_reward; parallax-eval
# then reads the same pan), with the weighting's y = 1 (distance.y=1.0: with this readout the
# best y on the online error before the perturbation; y = 0.1, the shipped default, was chosen
# for the last pan). Since session 7 the random start ends after a
# warm-up (train.start_jitter_presentations: 100 single, 50 for 5–10 cm, 33 for 5–20 cm), so the
# last 100 trials before the perturbation, which Table 2 averages, start from pan 0 as the
# paper's did; the 5–10 cm runs got 300 presentations so that their 150 before the perturbation
# hold the warm-up and those 100 trials.
# Extra arguments are Hydra overrides for every training job (they come last, so e.g.
# train.presentations=2000 lengthens every run). Environment: launch/ablation_lib.sh, plus
#   EVAL_ARGS      parallax-eval options (default: the grid 3.0, 3.5, …, 10.0 m, three held-out
#                  textures each, as in the report since session 11)
#   IMPROVEMENTS   the beyond-the-paper overrides above; IMPROVEMENTS=policy.reward_change_gain=0
#                  runs the paper's algorithm with the shipped settings, as the reports of
#                  sessions 2–4 did (the reward-change feature is on by default since session 9)
#   SINGLE_IMPROVEMENTS  overrides for the single-position runs only, after IMPROVEMENTS
#                  (default policy.reward_change_gain=30; none when IMPROVEMENTS is given)
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/ablation_lib.sh"
sweep="$(px_sweep_dir reproduce)"
unweighted="$(px_sweep_dir reproduce_unweighted)"
five_ten_c50="$(px_sweep_dir reproduce_5_10_c50)"
seeds="seed=${SEEDS:-0,1,2}"
read -ra improvements <<< "${IMPROVEMENTS-policy.feature_norm=difference env.initial_pan_jitter_deg=2 distance.lm.weight_decay=0.1 policy.eye_position_reference_m=0.5 policy.reward_change_gain=10 train.distance_readout=best_reward distance.y=1.0}"
if [[ -z "${IMPROVEMENTS+set}" ]]; then default_single_improvements="policy.reward_change_gain=30"; else default_single_improvements=""; fi
read -ra single_improvements <<< "${SINGLE_IMPROVEMENTS-$default_single_improvements}"
singles=paper_single_5,paper_single_7,paper_single_10,paper_single_13,paper_single_15,paper_single_20
status=0
px_sweep "$sweep" "experiment=$singles" "$seeds" train.presentations=400 train.start_jitter_presentations=100 \
  "${improvements[@]}" "${single_improvements[@]}" "$@" || status=$?
px_sweep "$sweep" experiment=paper_multi_5_10 "$seeds" train.presentations=300 train.start_jitter_presentations=50 \
  "${improvements[@]}" "$@" || status=$?
px_sweep "$sweep" experiment=paper_multi_5_20_weighted "$seeds" train.presentations=400 \
  train.start_jitter_presentations=33 distance.queue_size=100 perturbation.start_fraction=0.3325 \
  "${improvements[@]}" "$@" || status=$?

mapfile -t weighted < <(px_runs_with "$sweep" experiment=paper_multi_5_20_weighted)
mapfile -t five_ten < <(px_runs_with "$sweep" experiment=paper_multi_5_10)
if [[ -n "${PARALLAX_DRY_RUN:-}" ]]; then
  # nothing has run: name the runs the commands below would take
  weighted=("$sweep/<runs with experiment=paper_multi_5_20_weighted>")
  five_ten=("$sweep/<runs with experiment=paper_multi_5_10>")
fi

read -ra eval_args <<< "${EVAL_ARGS:---distances 3.0 3.5 4.0 4.5 5.0 5.5 6.0 6.5 7.0 7.5 8.0 8.5 9.0 9.5 10.0 --textures 3}"
for run in "${weighted[@]}" "${five_ten[@]}"; do
  # evaluate finished runs whose eval.json is missing or older than the checkpoint
  if [[ -n "${PARALLAX_DRY_RUN:-}" || ( -f "$run/summary.json" && ! "$run/eval.json" -nt "$run/checkpoint.pt" ) ]]; then
    px_run parallax-eval "$run" "${eval_args[@]}" || status=$?
    px_run parallax-eval "$run" "${eval_args[@]}" --checkpoint checkpoint_before_perturbation.pt \
      --out "$run/eval_before" || status=$?
  fi
done

px_run parallax-replay "${weighted[@]}" --out "$unweighted" distance.weighting=false || status=$?
# Table 4's 5–10 cm row: the paper's c = 300 never fills in 200 presentations, so its eye
# movements are replayed through a learner with c = 50 (scored on the same evals)
px_run parallax-replay "${five_ten[@]}" --out "$five_ten_c50" distance.queue_size=50 || status=$?

# The small trained models of the 5–20 cm weighted runs, before and after the perturbation, so
# that anyone can run parallax-eval on them without training: one folder per seed, a run
# directory of its own (config.yaml, checkpoint.pt, checkpoint_before_perturbation.pt).
for run in "${weighted[@]}"; do
  seed="$(sed -n 's/^seed: //p' "$run/config.yaml" 2>/dev/null || true)"
  if [[ -n "${PARALLAX_DRY_RUN:-}" || -f "$run/summary.json" ]]; then
    keep="$report_root/checkpoints/multi_5_20_weighted_seed${seed:-N}"
    px_run mkdir -p "$keep"
    px_run cp "$run/config.yaml" "$run/checkpoint.pt" "$run/checkpoint_before_perturbation.pt" "$keep/"
  fi
done

notes=()
if [[ -f "$report_root/notes.md" ]]; then
  # the reading of the results, written by hand and kept across re-runs
  notes=(--notes "$report_root/notes.md")
fi
px_report "$report_root" README.md "Reproducing the paper: Tables 2–5 and Figs. 7–11" paper \
  "$sweep" "$unweighted" "$five_ten_c50" "${notes[@]}"
exit "$status"
