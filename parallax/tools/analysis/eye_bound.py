"""How well any distance learner could do with the eye an evaluation measured (paper §3.5,
Tables 4–5): the eye's share of the distance error, apart from the learner's.

A panel at distance d is seen at lateral position l_p at the pan α*_p ≈ atan(l_p / d), so each
element q_p of s is nearly linear in 1/d. The estimator here fits, for every position p, the
line 1/d = a_p + b_p·q_p and averages the positions' answers with weights 1/(residual variance):
a small, physically motivated learner that cannot overfit 71 presentations. It is fitted to the
evaluation's own held-out presentations, leaving out each presentation in turn (leave-one-out),
so its error is what this eye's vectors allow when the learner is as good as such a line can be
(an oracle: the network learns from the training queue instead). Beside it, the run's own
network (a fresh distance learner with the run's settings, its queue the size of the training
folds) fitted to the same vectors by 5-fold cross-validation, and the line estimator on perfect
pans rounded to the action grid (the common step of policy.actions, from pan 0): the floor of
the action set itself.

    python -m parallax.tools.analysis.eye_bound EVAL_DIR…   # folders holding an eval.json

For each evaluation it prints the network's distance error (parallax-eval's), the two learners'
fitted to the evaluation's own eye movements, the action grid's floor, and the network's worst
presentation: its distance, its error there, and how far the eye ended from α* at the lateral
position where it missed most (one presentation whose eye stops short can carry a model's mean).
Beside them, what the eye's failures carry of the network's error: its median over the
presentations, how many presentations the eye ended more than ``--miss`` degrees from α* at some
lateral position, and the network's mean error over the others.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from functools import cache, reduce
from pathlib import Path

import numpy as np
import torch

from parallax.config import load_run_config
from parallax.distance.metrics import distance_error_by_range
from parallax.parts import distance_learner
from parallax.tools.analysis.baselines import target_pans
from parallax.tools.report.runs import EVAL_NAME, eval_run_dir, read_record, record_file

#: An eye that ends a presentation this far (degrees) from α* at some lateral position has failed
#: to pursue there: four to six times the paper's Table 2 errors at 5–13 cm (0.16–0.25°).
FAILED_MISS_DEG = 1.0


def position_line_estimates(train_pans, train_distances, pans) -> np.ndarray:
    """Distances for the vectors ``pans`` (M, r) from per-position lines 1/d = a_p + b_p·q_p
    fitted to (``train_pans`` (N, r), ``train_distances`` (N,)), combined by inverse residual
    variance."""
    train_pans, pans = np.asarray(train_pans, float), np.asarray(pans, float)
    inverse = 1.0 / np.asarray(train_distances, float)
    answers, weights = [], []
    for p in range(train_pans.shape[1]):
        design = np.column_stack([np.ones(len(inverse)), train_pans[:, p]])
        line, *_ = np.linalg.lstsq(design, inverse, rcond=None)
        residual = inverse - design @ line
        answers.append(line[0] + line[1] * pans[:, p])
        weights.append(1.0 / max(float(residual.var()), 1e-18))
    return 1.0 / np.average(np.array(answers), axis=0, weights=weights)


def leave_one_out(pans, distances) -> np.ndarray:
    """Each presentation's distance from the estimator fitted to all the others."""
    pans, distances = np.asarray(pans, float), np.asarray(distances, float)
    if len(distances) < 4:
        raise ValueError(f"leave-one-out needs at least 4 presentations, got {len(distances)}")
    keep = ~np.eye(len(distances), dtype=bool)
    return np.array(
        [
            position_line_estimates(pans[keep[i]], distances[keep[i]], pans[i : i + 1])[0]
            for i in range(len(distances))
        ]
    )


def network_cross_validated(cfg, pans, distances, folds: int = 5) -> np.ndarray:
    """Each presentation's distance from a fresh distance learner of the run's settings (its
    queue as large as a training fold, so that it fits once) trained on the other folds; the
    folds interleave, so each spans the distances."""
    pans, distances = np.asarray(pans, float), np.asarray(distances, float)
    estimates = np.empty_like(distances)
    for fold in range(folds):
        held = np.arange(len(distances)) % folds == fold
        settings = cfg.copy()
        settings.distance.queue_size = int((~held).sum())
        settings.distance.fit_from = None
        learner = distance_learner(settings)
        learner.observe_batch(pans[~held], list(distances[~held]))
        estimates[held] = learner.predict(pans[held])
    return estimates


@cache
def perfect_pans(lateral_positions: tuple[float, ...], distances: tuple[float, ...]) -> np.ndarray:
    """α* (degrees) at each lateral position (columns) for each distance (rows)."""
    return np.column_stack([target_pans(l, list(distances)) for l in lateral_positions])


def action_grid_step(actions) -> float:
    """The grid of pans reachable from 0 with these increments (degrees): their common step."""
    thousandths = [round(abs(float(a)) * 1000) for a in actions if round(abs(float(a)) * 1000)]
    return reduce(math.gcd, thousandths) / 1000.0


def eye_bound(eval_dir: str | Path, miss_deg: float = FAILED_MISS_DEG) -> dict:
    """The network's error, the two learners' fitted to the same eye movements, the action grid's
    floor and what the eye's failures (a miss over ``miss_deg``) carry of the network's error
    (module docstring) for the evaluation in ``eval_dir``."""
    path = Path(eval_dir) / EVAL_NAME  # or its compressed form
    if record_file(path) is None:
        raise FileNotFoundError(f"{eval_dir} holds no eval.json (run parallax-eval first)")
    result = json.loads(read_record(path))
    readout = result["readout"]
    distances = np.asarray(result["greedy_samples"]["grid"]["distances"], float)
    pans = np.asarray(result["greedy_samples_by_readout"][readout]["grid"]["pans"], float)
    cfg = load_run_config(eval_run_dir(eval_dir, result["run_dir"]))
    if int(cfg.train.threads) > 0:  # as in training: small matrices, and a shared machine
        torch.set_num_threads(int(cfg.train.threads))
    step = action_grid_step(cfg.policy.actions)
    laterals = tuple(float(l) for l in cfg.curriculum.lateral_positions)
    perfect = perfect_pans(laterals, tuple(float(d) for d in distances))
    rounded = np.round(perfect / step) * step
    network = result.get("distance", {}).get("by_range", {}).get("total", math.nan)
    errors = network_errors(result, distances)
    worst = worst_presentation(errors, pans, distances, perfect, laterals)
    failures = eye_failures(errors, pans, perfect, miss_deg)

    def error(estimates: np.ndarray) -> float:
        return distance_error_by_range(estimates, distances)["total"]

    return {
        "eval": str(eval_dir),
        "readout": readout,
        "trials": int(len(distances)),
        "network": float(network),
        "network_on_this_eye": error(network_cross_validated(cfg, pans, distances)),
        "lines_on_this_eye": error(leave_one_out(pans, distances)),
        "action_grid_step_deg": step,
        "floor": error(leave_one_out(rounded, distances)),
        **worst,
        **failures,
    }


def network_errors(result: dict, distances) -> np.ndarray | None:
    """parallax-eval's per-distance errors of the network (%) in the order of ``distances``
    (one presentation each unless told otherwise); None when the evaluation has none."""
    per_distance = result.get("distance", {}).get("per_distance", {})
    if not per_distance:
        return None
    return np.array([per_distance[f"{d:.2f}"] for d in distances])


def eye_failures(errors: np.ndarray | None, pans, perfect, miss_deg: float) -> dict:
    """The network's median error over the grid's presentations, how many presentations the eye
    ended more than ``miss_deg`` from α* at some lateral position, and the network's mean error
    over the other presentations."""
    if errors is None:
        return {
            "miss_deg": miss_deg,
            "network_median": math.nan,
            "eye_failures": 0,
            "network_without_failures": math.nan,
        }
    failed = np.abs(np.asarray(pans) - perfect).max(axis=1) > miss_deg
    return {
        "miss_deg": miss_deg,
        "network_median": float(np.median(errors)),
        "eye_failures": int(failed.sum()),
        "network_without_failures": float(errors[~failed].mean()) if (~failed).any() else math.nan,
    }


def worst_presentation(errors: np.ndarray | None, pans, distances, perfect, laterals) -> dict:
    """The grid distance the network judged worst (parallax-eval's error there, the mean over its
    textures) and the eye's largest miss |q_p − α*_p| (degrees) on the first presentation at that
    distance, with its lateral position (cm). parallax-eval shows one texture per distance
    unless told otherwise, so the presentation is then the worst one."""
    if errors is None:
        return {
            "worst_distance_m": math.nan,
            "worst_error": math.nan,
            "worst_eye_miss_deg": math.nan,
            "worst_eye_miss_at_cm": math.nan,
        }
    row = int(np.argmax(errors))
    misses = np.abs(pans[row] - perfect[row])
    column = int(np.argmax(misses))
    return {
        "worst_distance_m": float(distances[row]),
        "worst_error": float(errors[row]),
        "worst_eye_miss_deg": float(misses[column]),
        "worst_eye_miss_at_cm": round(laterals[column] * 100, 6),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.eye_bound", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("evals", nargs="+", metavar="EVAL_DIR", help="folders with an eval.json")
    parser.add_argument("--json", default=None, help="also write the rows to this JSON file")
    parser.add_argument(
        "--miss",
        type=float,
        default=FAILED_MISS_DEG,
        metavar="DEG",
        help="a presentation whose eye ends this far from α* at some position has failed "
        f"(default {FAILED_MISS_DEG:g})",
    )
    args = parser.parse_args(argv)
    if not args.miss > 0:
        print(f"eye_bound: error: --miss must be positive, got {args.miss:g}", file=sys.stderr)
        sys.exit(2)
    try:
        rows = [eye_bound(folder, args.miss) for folder in args.evals]
    except (FileNotFoundError, ValueError, KeyError) as exc:
        print(f"eye_bound: error: {exc}", file=sys.stderr)
        sys.exit(2)
    print(
        "| evaluation | trials | network as trained (%) | network fitted to this eye (%) | "
        "lines fitted to this eye (%) | action grid floor (%) | worst presentation: distance, "
        "network's error, the eye's largest miss | network's median (%) | "
        f"eye off by more than {args.miss:g}° | network on the others (%) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['eval']} | {row['trials']} | {row['network']:.2f} | "
            f"{row['network_on_this_eye']:.2f} | {row['lines_on_this_eye']:.2f} | "
            f"{row['floor']:.2f} | {row['worst_distance_m']:.2f} m, {row['worst_error']:.1f} %, "
            f"{row['worst_eye_miss_deg']:.2f}° at {row['worst_eye_miss_at_cm']:g} cm | "
            f"{row['network_median']:.2f} | {row['eye_failures']} | "
            f"{row['network_without_failures']:.2f} |"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
