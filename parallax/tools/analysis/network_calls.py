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
block's end, and the eye's recent error (eq. 16, the trainer's window) there.

``--replay KEY=VALUE…`` replays each run's distance learner with those settings first
(parallax-replay: the same eye movements) and reads the same figures from the replay, with the
online error of each block's own predictions: whether a network trained that way follows the eye
as it changes, e.g. ``--replay distance.warm_start=false`` (a new network at every fit). A run
still training is read, and replayed, as far as its record goes.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from tqdm import tqdm

from parallax.config import load_run_config
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
    return [block_figures(part, max_fail) for part in _blocks(records, blocks)]


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
    rows = []
    for part in _blocks(records, blocks):
        row = block_figures(part, max_fail)
        if row["fits"]:  # only max_fail is known for a replayed fit
            row["stopped"] = {rule: None for rule in row["stopped"]}
            row["stopped"]["max_fail"] = sum(r["lm_stopped_max_fail"] for r in part) / row["fits"]
        own = [e for r in part for e in r["errors"]]
        row["distance_error"] = sum(own) / len(own) if own else None
        rows.append(row)
    return rows


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
            "block's own online predictions"
        )
    stops = " | ".join(f"stopped by {rule}" for rule in (*RULES, "epochs"))
    print(
        f"| run | presentations | fits | unchanged | mean epochs | {stops} | distance error | "
        "eye (°) |"
    )
    print("|---" * (8 + len(RULES)) + "|")
    for run, rows in results:
        for row in rows:
            epochs = "–" if row["epochs"] is None else f"{row['epochs']:.2f}"
            error, eye = row["distance_error"], row["eye_mae"]
            shares = " | ".join(_share(row["stopped"][rule]) for rule in (*RULES, "epochs"))
            print(
                f"| {run} | {row['first']}–{row['last']} | {row['fits']} | "
                f"{_share(row['unchanged'])} | {epochs} | {shares} | "
                f"{'–' if error is None else f'{error:.2f} %'} | "
                f"{'–' if eye is None else f'{eye:.3f}'} |"
            )


if __name__ == "__main__":
    main(sys.argv[1:])
