"""`python -m parallax.tools.analysis.network_calls RUN...`: what the retraining of a run's
distance network did (paper §3.5: trained by Levenberg–Marquardt each time a new s joins S), read
from its logged `metrics.jsonl`.

With a validation stop (``distance.validation_fraction`` > 0, as MATLAB's ``train`` divides the
data), a fit keeps the weights of its epoch with the lowest validation error. One that stops by
``max_fail`` after exactly ``max_fail`` accepted epochs found no epoch better than the weights
it started from: with a warm start (``distance.warm_start``), it leaves the network as it was.
Per run and block of presentations (before and after §5's perturbation, or ``--blocks N``) this
prints the fits logged, the share that left the network unchanged, their mean accepted epochs,
the share that each rule stopped, the online distance error (total, the trainer's window) at the
block's end, the eye's recent error (eq. 16, the trainer's window) there, and the eye as the
network sees it: the block's vectors s against α* (degrees), split into their mean |error|, their
bias (the mean signed error, which a network can learn), their scatter (the sd about each lateral
position's bias, which it cannot) and the share of presentations that missed α* by more than
``eye_bound.FAILED_MISS_DEG`` at some lateral position. ``--positions`` also prints, for each phase
(before and after the perturbation), the same split at every lateral position, and the share of
presentations missed in each of Table 4's distance ranges: where the eye's misses are.

``--replay KEY=VALUE…`` replays each run's distance learner with those settings first
(parallax-replay: the same eye movements) and reads the same figures from the replay, with the
online error of each block's own predictions, mean and median: whether a network trained that
way follows the eye as it changes, e.g. ``--replay distance.warm_start=false`` (a new network at
every fit). Beside them, what the block's eye allows a network of those settings: a fresh one
fitted to the block's own vectors s, each predicted by 5-fold cross-validation
(``eye_bound.network_cross_validated``), mean and median. The mean error is carried by the few
presentations where the eye failed at some lateral position; the median shows the rest. A run
still training is read, and replayed, as far as its record goes.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

from parallax.config import load_run_config
from parallax.distance.metrics import range_masks
from parallax.readouts import READOUTS
from parallax.tools.analysis.eye_bound import (
    FAILED_MISS_DEG,
    network_cross_validated,
    perfect_pans,
)
from parallax.tools.replay import replay
from parallax.tools.report.runs import read_metrics

#: The stop rules a fit logs (``lm_stopped_<rule>``); a fit that none stopped used its epochs.
RULES = ("max_fail", "min_grad", "mu_max", "non_finite")


def block_figures(records: list[dict], max_fail: int | None) -> dict:
    """One block's figures: fits, unchanged (share of fits; None without a validation stop or
    a warm start: ``max_fail`` None),
    mean epochs, the share stopped by each rule and by none ("epochs"), the distance error at its
    end (None before the first prediction)."""
    fits = [r for r in records if r.get("lm_trained")]
    share = {rule: 0.0 for rule in (*RULES, "epochs")}
    unchanged = None
    if fits:
        for rule in RULES:
            share[rule] = sum(bool(r[f"lm_stopped_{rule}"]) for r in fits) / len(fits)
        share["epochs"] = 1.0 - sum(share[rule] for rule in RULES)
        if max_fail is not None:
            kept = [r for r in fits if r["lm_stopped_max_fail"] and r["lm_epochs"] == max_fail]
            unchanged = len(kept) / len(fits)
    return {
        "first": records[0]["presentation"],
        "last": records[-1]["presentation"],
        "fits": len(fits),
        "unchanged": unchanged,
        "epochs": sum(r["lm_epochs"] for r in fits) / len(fits) if fits else None,
        "stopped": share,
        "distance_error": (records[-1].get("distance_error") or {}).get("total"),
        "eye_mae": records[-1].get("mae_recent"),
    }


def network_calls(run_dir: str | Path, blocks: int | None = None) -> list[dict]:
    """The run's blocks (see the module's docstring), in order."""
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    records = read_metrics(run_dir)
    if not records:
        raise ValueError(f"{run_dir}: metrics.jsonl has no presentations")
    if "lm_trained" not in records[-1]:
        raise ValueError(f"{run_dir}: metrics.jsonl has no distance-learner fields (lm_*)")
    # a fit that keeps its starting weights leaves the network unchanged only when it has a
    # validation stop and starts from the last fit's weights
    kept_is_unchanged = float(cfg.distance.validation_fraction) > 0 and cfg.distance.warm_start
    max_fail = int(cfg.distance.max_fail) if kept_is_unchanged else None
    key = readout_key(cfg)
    return [
        {**block_figures(part, max_fail), "eye": eye_figures(cfg, part, key)}
        for part in _blocks(records, blocks)
    ]


def readout_key(cfg) -> str:
    """The metrics key of the vectors s the run's distance learner reads."""
    return READOUTS[str(cfg.train.distance_readout)].key


def _vectors(records: list[dict], key: str) -> tuple[list, list]:
    """The presentations' vectors s (``key``) and their distances, as logged."""
    pans = [p for r in records for p in r.get(key) or []]
    return pans, [d for r in records for d in r.get("distances") or []]


def _pan_errors(cfg, records: list[dict], key: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The vectors s (``key``) minus α* (degrees, presentations × lateral positions) and the
    presentations' distances; None without s."""
    pans, distances = _vectors(records, key)
    if not pans or len(pans) != len(distances):
        return None
    laterals = tuple(float(l) for l in cfg.curriculum.lateral_positions)
    grid = sorted(set(distances))
    targets = perfect_pans(laterals, tuple(grid))[[grid.index(d) for d in distances]]
    return np.asarray(pans, float) - targets, np.asarray(distances, float)


def eye_by_position(cfg, records: list[dict], key: str) -> dict | None:
    """:func:`eye_figures` at each lateral position (by its label in cm), and the share of
    presentations with a miss beyond FAILED_MISS_DEG in each distance range; None without s."""
    found = _pan_errors(cfg, records, key)
    if found is None:
        return None
    errors, distances = found
    positions = {}
    for k, lateral in enumerate(cfg.curriculum.lateral_positions):
        e = errors[:, k]
        positions[f"{100 * float(lateral):g}"] = {
            "mae": float(np.abs(e).mean()),
            "bias": float(e.mean()),
            "scatter": float(e.std()),
            "missed": float((np.abs(e) > FAILED_MISS_DEG).mean()),
        }
    missed = (np.abs(errors) > FAILED_MISS_DEG).any(axis=1)
    ranges = {
        name: float(missed[inside].mean()) if inside.any() else None
        for name, inside in range_masks(distances).items()
    }
    return {"positions": positions, "ranges": ranges}


def eye_figures(cfg, records: list[dict], key: str) -> dict | None:
    """The block's vectors s (``key``) against α* at each lateral position, in degrees: mean
    |error|, bias (mean signed error), scatter (sd about each position's own bias) and the share
    of presentations with a miss beyond FAILED_MISS_DEG at some position; None without s."""
    found = _pan_errors(cfg, records, key)
    if found is None:
        return None
    errors = found[0]
    return {
        "mae": float(np.abs(errors).mean()),
        "bias": float(errors.mean()),
        "scatter": float((errors - errors.mean(axis=0)).std()),
        "missed": float((np.abs(errors) > FAILED_MISS_DEG).any(axis=1).mean()),
    }


def replayed_network_calls(
    run_dir: str | Path, overrides: Sequence[str], blocks: int | None = None
) -> list[dict]:
    """:func:`network_calls` of the run's distance learner replayed with ``overrides``; each
    block's distance error is the mean of its own online predictions (|d̂ − d|/d, %)."""
    run_dir = Path(run_dir)
    result = replay(run_dir, list(overrides), so_far=True)  # a run still training: so far
    cfg = result["config"]
    kept_is_unchanged = float(cfg.distance.validation_fraction) > 0 and cfg.distance.warm_start
    fits = {presentation: (epochs, stopped) for presentation, epochs, stopped in result["fits"]}
    errors: dict[int, list[float]] = {}
    for presentation, predicted, truth in result["online"]:
        errors.setdefault(presentation, []).append(100.0 * abs(predicted - truth) / truth)
    records = []
    for source in read_metrics(run_dir):
        presentation = int(source["presentation"])
        epochs, stopped = fits.get(presentation, (0.0, 0.0))
        records.append(
            {
                "presentation": presentation,
                "perturbed": source.get("perturbed"),
                "mae_recent": source.get("mae_recent"),
                "lm_trained": presentation in fits,
                "lm_epochs": epochs,
                "lm_stopped_max_fail": stopped,
                **{f"lm_stopped_{rule}": 0.0 for rule in RULES if rule != "max_fail"},
                "errors": errors.get(presentation, []),
            }
        )
    max_fail = int(cfg.distance.max_fail) if kept_is_unchanged else None
    key = readout_key(cfg)
    rows = []
    for part, sources in zip(_blocks(records, blocks), _blocks(read_metrics(run_dir), blocks)):
        row = block_figures(part, max_fail)
        if row["fits"]:  # only max_fail is known for a replayed fit
            row["stopped"] = {rule: None for rule in row["stopped"]}
            row["stopped"]["max_fail"] = sum(r["lm_stopped_max_fail"] for r in part) / row["fits"]
        own = [e for r in part for e in r["errors"]]
        row["distance_error"] = float(np.mean(own)) if own else None
        row["distance_error_median"] = float(np.median(own)) if own else None
        row["eye_allows"] = eye_allows(cfg, sources, key)
        row["eye"] = eye_figures(cfg, sources, key)
        rows.append(row)
    return rows


def eye_allows(cfg, records: list[dict], key: str, folds: int = 5) -> dict | None:
    """Mean and median error (%) of a fresh network of ``cfg``'s settings fitted to these
    presentations' own vectors s (``key``), each predicted by ``folds``-fold cross-validation;
    None for a block too small to be split so."""
    pans, distances = _vectors(records, key)
    if len(pans) != len(distances) or len(distances) < 4 * folds:
        return None
    estimates = network_cross_validated(cfg, pans, distances, folds)
    errors = 100.0 * np.abs(estimates - np.asarray(distances)) / np.asarray(distances)
    return {"mean": float(errors.mean()), "median": float(np.median(errors))}


def _blocks(records: list[dict], blocks: int | None) -> list[list[dict]]:
    if blocks is None:
        parts = [
            [r for r in records if not r.get("perturbed")],
            [r for r in records if r.get("perturbed")],
        ]
    else:
        parts = [records[k : k + blocks] for k in range(0, len(records), blocks)]
    return [part for part in parts if part]


def _share(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f} %"


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.network_calls",
        description=__doc__.split("\n\n")[0],
    )
    parser.add_argument("runs", nargs="+", help="run directories (with metrics.jsonl)")
    parser.add_argument(
        "--blocks",
        type=int,
        help="presentations a block (default: before and after §5's perturbation)",
    )
    parser.add_argument(
        "--positions",
        action="store_true",
        help="also print, per phase, the eye's vectors at each lateral position and distance range",
    )
    parser.add_argument(
        "--replay",
        nargs="+",
        metavar="KEY=VALUE",
        help="replay each run's distance learner with these settings first",
    )
    args = parser.parse_args(argv)
    if args.blocks is not None and args.blocks < 1:
        parser.exit(2, f"{parser.prog}: error: --blocks must be at least 1, got {args.blocks}\n")
    results = []
    for run in tqdm(args.runs, desc="runs", disable=len(args.runs) < 2 and not args.replay):
        try:
            if args.replay:
                results.append((run, replayed_network_calls(run, args.replay, args.blocks)))
            else:
                results.append((run, network_calls(run, args.blocks)))
        except (OSError, ValueError) as exc:
            parser.exit(2, f"{parser.prog}: error: {str(exc).splitlines()[0]}\n")
    if args.replay:
        print(
            f"distance learner replayed with {' '.join(args.replay)}; distance error: each "
            "block's own online predictions, mean (median); what the eye allows: a fresh "
            "network of those settings on the block's own vectors, 5-fold cross-validated"
        )
    stops = " | ".join(f"stopped by {rule}" for rule in (*RULES, "epochs"))
    allows = " what the eye allows |" if args.replay else ""
    print(
        f"| run | presentations | fits | unchanged | mean epochs | {stops} | distance error |"
        f"{allows} eye, recent (°) | s: mean abs error (°) | s: bias (°) | s: scatter (°) | "
        f"s: missed by > {FAILED_MISS_DEG:g}° |"
    )
    print("|---" * (12 + len(RULES) + bool(args.replay)) + "|")
    for run, rows in results:
        for row in rows:
            epochs = "–" if row["epochs"] is None else f"{row['epochs']:.2f}"
            eye = row["eye_mae"]
            shares = " | ".join(_share(row["stopped"][rule]) for rule in (*RULES, "epochs"))
            error = _error(row["distance_error"], row.get("distance_error_median"))
            if args.replay:
                allowed = row["eye_allows"] or {}
                error += f" | {_error(allowed.get('mean'), allowed.get('median'))}"
            s = row["eye"]
            vectors = (
                "– | – | – | –"
                if s is None
                else f"{s['mae']:.3f} | {s['bias']:+.3f} | {s['scatter']:.3f} | "
                f"{_share(s['missed'])}"
            )
            print(
                f"| {run} | {row['first']}–{row['last']} | {row['fits']} | "
                f"{_share(row['unchanged'])} | {epochs} | {shares} | {error} | "
                f"{'–' if eye is None else f'{eye:.3f}'} | {vectors} |"
            )

    if args.positions:
        for run in args.runs:
            print_positions(run)


def print_positions(run: str) -> None:
    """The ``--positions`` tables of one run, per phase."""
    cfg = load_run_config(run)
    key = readout_key(cfg)
    for part in _blocks(read_metrics(run), None):
        found = eye_by_position(cfg, part, key)
        if found is None:
            continue
        phase = "after the perturbation" if part[0].get("perturbed") else "before the perturbation"
        first, last = part[0]["presentation"], part[-1]["presentation"]
        print(f"\n{run}, {phase} (presentations {first}–{last}):")
        print(
            f"| lateral position | s: mean abs error (°) | s: bias (°) | s: scatter (°) | "
            f"s: missed by > {FAILED_MISS_DEG:g}° |"
        )
        print("|---|---|---|---|---|")
        for label, figures in found["positions"].items():
            print(
                f"| {label} cm | {figures['mae']:.3f} | {figures['bias']:+.3f} | "
                f"{figures['scatter']:.3f} | {_share(figures['missed'])} |"
            )
        ranges = ", ".join(f"{name} m {_share(share)}" for name, share in found["ranges"].items())
        print(f"\npresentations missed at some lateral position, by distance: {ranges}")


def _error(mean: float | None, median: float | None = None) -> str:
    if mean is None:
        return "–"
    return f"{mean:.2f} %" + ("" if median is None else f" ({median:.2f} %)")


if __name__ == "__main__":
    main(sys.argv[1:])
