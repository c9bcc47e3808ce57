"""`python -m parallax.tools.analysis.convergence RUN...`: whether a run trained long enough, and
whether its critic stayed bounded, read from its logged `metrics.jsonl`.

A run of Tables 2–3 has two phases, before and after §5's perturbation. For each phase it prints
the recent eye-movement MAE at the phase's end (eq. 16 over metrics.summary_trials trials, the
tables' "last 100 trials", worst lateral position; with ``--positions`` every position's) and
its trend: the mean of that figure over the phase's last ``--tail`` of presentations less its
mean over the ``--tail`` before. A phase is flat when the trend is within ±``--flat`` degrees
(means over blocks, so that the noise of a 100-trial figure does not hide a flat end, nor a slow
drift pass for one). Beside the trend, its 95 % interval: each of the two blocks cut into pieces
as long as the figure's memory (metrics.summary_trials presentations, over which one position's
last trials reach back), the pieces' means taken as independent, a t interval on the difference
of the blocks' means; none where a block holds fewer than two pieces or the run has no
config.yaml. A trend beyond ±``--flat`` whose interval holds 0 is not told apart from noise.
Then the critic's scale, mean |v·φ| (peak and last; it grows without bound
when the natural actor-critic diverges, paper §3.4) and the policy's entropy at the end
(ln 7 ≈ 1.95 is uniform over the seven pan steps).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path

from scipy import stats

from parallax.config.plumbing import load_run_config
from parallax.tools.report.runs import read_metrics

#: The share of a phase in each of the two blocks compared, and the trend (degrees) of a flat
#: phase.
TAIL, FLAT = 0.2, 0.02


def _worst(record: dict) -> float:
    return max(record["mae_recent_per_position"].values())


def trend_interval(
    last: Sequence[float], before: Sequence[float], memory: int | None
) -> tuple[float, float] | None:
    """The 95 % interval of the trend mean(last) − mean(before): its half-width from pieces of
    ``memory`` values of each block taken as independent (pooled variance, Student's t); None
    with fewer than two whole pieces in a block, or no ``memory``."""
    if not memory or memory < 1:
        return None
    pieces = []
    for values in (last, before):
        whole = len(values) // memory
        if whole < 2:
            return None
        cut = values[len(values) - whole * memory :]  # the latest whole pieces
        pieces.append([statistics.fmean(cut[i * memory : (i + 1) * memory]) for i in range(whole)])
    (a, b), dof = pieces, len(pieces[0]) + len(pieces[1]) - 2
    pooled = ((len(a) - 1) * statistics.variance(a) + (len(b) - 1) * statistics.variance(b)) / dof
    half = stats.t.ppf(0.975, dof) * (pooled * (1 / len(a) + 1 / len(b))) ** 0.5
    trend = statistics.fmean(last) - statistics.fmean(before)
    return trend - half, trend + half


def _phase(records: list[dict], tail: float, flat: float, memory: int | None) -> dict | None:
    if not records:
        return None
    block = max(1, round(len(records) * tail))
    worst = [_worst(r) for r in records]
    last, before = worst[-block:], worst[-2 * block : -block] or worst[-block:]
    trend = sum(last) / len(last) - sum(before) / len(before)
    return {
        "presentations": len(records),
        "mae_recent": worst[-1],
        "per_position": dict(records[-1]["mae_recent_per_position"]),
        "trend": trend,
        "trend_interval": trend_interval(last, before, memory),
        "flat": abs(trend) <= flat,
    }


def figure_memory(run_dir: Path) -> int | None:
    """How many presentations one position's last-trials figure reaches back: the run's
    metrics.summary_trials (one trial per position and presentation); None without its
    config.yaml."""
    try:
        return int(load_run_config(run_dir).metrics.summary_trials)
    except FileNotFoundError:
        return None


def blocks(records: list[dict], size: int) -> list[dict]:
    """The worst position's recent MAE averaged over consecutive blocks of ``size``
    presentations: [{"first", "last", "mae", "perturbed"}], a learning curve that the noise of
    single 100-trial figures does not hide."""
    curve = []
    for start in range(0, len(records), size):
        block = records[start : start + size]
        curve.append(
            {
                "first": block[0]["presentation"],
                "last": block[-1]["presentation"],
                "mae": sum(_worst(r) for r in block) / len(block),
                "perturbed": bool(block[-1].get("perturbed")),
            }
        )
    return curve


def convergence(
    run_dir: str | Path, tail: float = TAIL, flat: float = FLAT, block: int | None = None
) -> dict:
    """{"before", "after": {presentations, mae_recent, per_position, trend, flat} or None,
    "critic_peak", "critic_last", "entropy_last", and with ``block`` "blocks" (see
    :func:`blocks`)} for one run directory."""
    records = read_metrics(Path(run_dir))
    if not records:
        raise ValueError(f"{run_dir}: metrics.jsonl holds no presentations")
    scales = [r["policy_critic_scale"] for r in records if "policy_critic_scale" in r]
    memory = figure_memory(Path(run_dir))
    return {
        **({"blocks": blocks(records, block)} if block else {}),
        "before": _phase([r for r in records if not r.get("perturbed")], tail, flat, memory),
        "after": _phase([r for r in records if r.get("perturbed")], tail, flat, memory),
        "critic_peak": max(scales) if scales else None,
        "critic_last": scales[-1] if scales else None,
        "entropy_last": records[-1].get("policy_entropy"),
    }


def _cell(phase: dict | None) -> str:
    if phase is None:
        return "–"
    mark = "flat" if phase["flat"] else "moving"
    interval = phase.get("trend_interval")
    span = "" if interval is None else f" [{interval[0]:+.3f}, {interval[1]:+.3f}]"
    return (
        f"{phase['mae_recent']:.3f}° ({mark}: {phase['trend']:+.3f}°{span}, "
        f"{phase['presentations']})"
    )


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.convergence", description=__doc__.split("\n")[0]
    )
    parser.add_argument("runs", nargs="+", help="run directories")
    parser.add_argument("--tail", type=float, default=TAIL, help="share of each phase checked")
    parser.add_argument(
        "--flat", type=float, default=FLAT, help="degrees a flat phase's trend may reach"
    )
    parser.add_argument(
        "--blocks",
        type=int,
        help="also print the learning curve in blocks of this many presentations",
    )
    parser.add_argument(
        "--positions",
        action="store_true",
        help="also print every lateral position's figure at the end of each phase",
    )
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args(argv)
    if not 0 < args.tail <= 1:
        parser.error(f"--tail must lie in (0, 1], got {args.tail}")
    if args.blocks is not None and args.blocks < 1:
        parser.error(f"--blocks must be a positive number of presentations, got {args.blocks}")
    results = {}
    print("| run | before the perturbation | after | critic peak / last | entropy |")
    print("|---|---|---|---|---|")
    for run in args.runs:
        try:
            found = convergence(run, args.tail, args.flat, args.blocks)
        except (OSError, ValueError) as error:
            print(f"convergence: {error}", file=sys.stderr)
            sys.exit(2)
        results[run] = found
        critic = (
            "–"
            if found["critic_peak"] is None
            else f"{found['critic_peak']:.3g} / {found['critic_last']:.3g}"
        )
        entropy = found["entropy_last"]
        print(
            f"| {Path(run).name} | {_cell(found['before'])} | {_cell(found['after'])} | {critic} "
            f"| {'–' if entropy is None else f'{entropy:.2f}'} |"
        )
    for run, found in results.items():
        if "blocks" in found:
            curve = ", ".join(
                f"{b['first']}–{b['last']}{' (perturbed)' if b['perturbed'] else ''}: "
                f"{b['mae']:.3f}°"
                for b in found["blocks"]
            )
            print(f"\n{Path(run).name}, mean recent MAE by block: {curve}")
    if args.positions:
        for run, found in results.items():
            for name in ("before", "after"):
                if found[name] is not None:
                    figures = ", ".join(
                        f"{position} cm: {mae:.3f}°"
                        for position, mae in found[name]["per_position"].items()
                    )
                    print(f"\n{Path(run).name}, recent MAE by lateral position, {name}: {figures}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
