"""Distance from the robot's own body (beyond the paper: its second future work, §7), measured.

The distance learner of §3.5 is told the true distance. With ``distance.targets=odometry`` it
learns instead from the robot's walks to the panel (parallax.envs.walk): strides counted until
its hand touches the panel, times the stride it believes it has. The walk comes after the sweep,
with its own random stream, so a finished supervised run's eye movements serve both learners:
each figure here is a ``parallax-replay`` of such a run (its metrics.jsonl and its parallax-eval
samples, held-out photographs), with the overrides printed beside it.

- **Table**: held-out error (metres of the robot's own, converted with its nominal stride, against
  the slip-free walk to touch) for walk fraction × stride slip, and the ratio to the supervised
  learner on the same eye movements. With a fraction f < 1 only f of the presentations bring a
  target, so fits start once the queue holds round(f·c) of them (``distance.fit_from``), after as
  many presentations as the supervised learner waits.
- **Growth spurt**: the true stride grows by ``--growth`` part-way (env.walk.growth_*) while the
  robot keeps its nominal stride: the online error in body units before and after, and the
  presentations until it is back within 1.2× of its level before the spurt.

    python -m parallax.tools.analysis.embodied RUN_OR_MULTIRUN… --out DIR [--cache DIR]

With ``--cache``, each source's replays are kept there and reused while the source's eval is
older, so a run added later costs only its own replays.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from parallax.config import load_run_config
from parallax.tools.console import footer, header, progress
from parallax.tools.replay import ReplayError, find_sources, replay
from parallax.tools.report.groups import mean_sd
from parallax.tools.report.runs import record_file

FRACTIONS = (1.0, 0.3, 0.1)
SLIPS = (0.0, 0.02, 0.05)
#: The spurt: the body's stride × 1.1 from 60 % of the run on (after §5's perturbation, which the
#: recipe switches on at a third), leaving 160 of 400 presentations to adapt.
GROWTH_FACTOR = 1.1
GROWTH_START_FRACTION = 0.6
#: Recovery: the rolling mean of the online error over this many presentations back within
#: RECOVERED × its mean over the same number of presentations before the spurt.
ROLLING = 20
RECOVERED = 1.2
FINAL_EVAL = "eval.json"
BEFORE_EVAL = "eval_before/eval.json"


def cell_overrides(queue_size: int, fraction: float, slip: float) -> list[str]:
    """The replay overrides of one table cell."""
    fit_from = "null" if fraction == 1.0 else str(max(1, round(queue_size * fraction)))
    return [
        "distance.targets=odometry",
        f"distance.odometry.walk_fraction={fraction:g}",
        f"env.walk.stride_slip={slip:g}",
        f"distance.fit_from={fit_from}",
    ]


def growth_overrides(factor: float, start_fraction: float) -> list[str]:
    return [
        "distance.targets=odometry",
        f"env.walk.growth_factor={factor:g}",
        f"env.walk.growth_start_fraction={start_fraction:g}",
    ]


def eval_scores(result: dict, name: str) -> dict | None:
    """Held-out error of a replay's rescored eval ``name``: MAE in metres, total %, trials."""
    evaluation = result["evals"].get(name)
    if evaluation is None or "distance" not in evaluation:
        return None
    scores = {
        "mae_m": evaluation["distance"]["mae_m"],
        "total_pct": evaluation["distance"]["by_range"]["total"],
        "trials": evaluation["distance"]["trials"],
        "distances": len(evaluation["distance"]["per_distance"]),
    }
    between = evaluation.get("distance_between_grid")
    if between is not None:
        scores["between_mae_m"] = between["mae_m"]
        scores["between_trials"] = between["trials"]
    return scores


def recovery(online: Sequence[tuple[int, float, float]], start: int) -> dict:
    """The online error (% of the truth, i.e. in body units) around a spurt at presentation
    ``start``: its level before, its peak after, and the presentations until recovered."""
    presentations = np.array([p for p, _, _ in online])
    errors = np.array([100.0 * abs(d - t) / t for _, d, t in online])
    before = errors[(presentations > start - ROLLING) & (presentations <= start)]
    after_at, after = presentations[presentations > start], errors[presentations > start]
    level = float(before.mean()) if before.size else float("nan")
    rolling = np.convolve(after, np.ones(ROLLING) / ROLLING, mode="valid")
    back = np.flatnonzero(rolling <= RECOVERED * level)
    return {
        "before_pct": level,
        "peak_pct": float(rolling.max()) if rolling.size else float("nan"),
        "end_pct": float(rolling[-1]) if rolling.size else float("nan"),
        "presentations_to_recover": int(after_at[back[0]] - start) if back.size else None,
        "curve": {
            "presentation": presentations.tolist(),
            "error_pct": errors.tolist(),
        },
    }


def study(sources: Sequence[Path], cache: Path | None = None, bar=None) -> dict:
    """Every replay of the table and the spurt, for each source run. With ``cache``, each
    source's replays are kept there (``<run>.json``) and reused while its eval is older.
    ``bar``: a progress bar moved on by each source's replays (:data:`REPLAYS`)."""
    rows: list[dict] = []
    growth: list[dict] = []
    for source in sources:
        kept = None if cache is None else cache / f"{source.name}.json"
        if kept is not None and kept.is_file() and kept.stat().st_mtime > _eval_time(source):
            one = json.loads(kept.read_text())
        else:
            one = study_one(source)
            if kept is not None:
                kept.parent.mkdir(parents=True, exist_ok=True)
                kept.write_text(json.dumps(one) + "\n")
        rows += one["rows"]
        growth += one["growth"]
        if bar is not None:
            bar.update(REPLAYS)
    return {"rows": rows, "growth": growth}


def _eval_time(source: Path) -> float:
    path = record_file(source / FINAL_EVAL)  # or its compressed form
    return path.stat().st_mtime if path is not None else 0.0


#: The replays of one source: the supervised learner, each walk fraction × slip, the spurt.
REPLAYS = 1 + len(FRACTIONS) * len(SLIPS) + 1


def study_one(source: Path) -> dict:
    """The replays of one source run: the supervised learner, every cell, and the spurt."""
    cfg = load_run_config(source)
    queue = int(cfg.distance.queue_size)
    supervised = replay(source, [])
    base = {"source": str(source), "seed": int(cfg.seed)}
    rows = [
        {
            **base,
            "targets": "supervisor",
            "overrides": [],
            "final": eval_scores(supervised, FINAL_EVAL),
            "before": eval_scores(supervised, BEFORE_EVAL),
        }
    ]
    for fraction in FRACTIONS:
        for slip in SLIPS:
            overrides = cell_overrides(queue, fraction, slip)
            result = replay(source, overrides)
            rows.append(
                {
                    **base,
                    "targets": "odometry",
                    "walk_fraction": fraction,
                    "stride_slip": slip,
                    "overrides": overrides,
                    "final": eval_scores(result, FINAL_EVAL),
                    "before": eval_scores(result, BEFORE_EVAL),
                }
            )
            print(f"[embodied] {source.name} {' '.join(overrides)}: {rows[-1]['final']}")
    overrides = growth_overrides(GROWTH_FACTOR, GROWTH_START_FRACTION)
    result = replay(source, overrides)
    start = round(GROWTH_START_FRACTION * int(cfg.train.presentations))
    growth = {
        **base,
        "overrides": overrides,
        "growth_presentation": start,
        "online": recovery(result["online"], start),
        "final": eval_scores(result, FINAL_EVAL),
        "before": eval_scores(result, BEFORE_EVAL),
    }
    print(f"[embodied] {source.name} growth: {growth['online']['before_pct']:.2f} %")
    return {"rows": rows, "growth": [growth]}


def table(results: dict) -> str:
    """The walk fraction × slip table (final models, held-out photographs), as Markdown."""
    rows = results["rows"]
    supervised = {r["seed"]: r["final"] for r in rows if r["targets"] == "supervisor"}
    seeds = sorted(supervised)
    trials = sorted({(r["final"]["trials"], r["final"]["distances"]) for r in rows if r["final"]})
    lines = [
        "Held-out photographs, "
        + ", ".join(f"{n} trials at {k} distances" for n, k in trials)
        + " per model, "
        f"{len(seeds)} seeds; error in metres: mean ± sd over seeds (ratio to the supervised "
        "learner on the same eye movements).",
        "",
        "| walked | " + " | ".join(f"slip {s:.0%}" for s in SLIPS) + " |",
        "|---|" + "---|" * len(SLIPS),
    ]
    base = [supervised[s]["mae_m"] for s in seeds if supervised[s]]
    lines.append(f"| supervisor | {mean_sd(base, 3)} m |" + " |" * (len(SLIPS) - 1))
    for fraction in FRACTIONS:
        cells = []
        for slip in SLIPS:
            got = [
                r
                for r in rows
                if r["targets"] == "odometry"
                and r["walk_fraction"] == fraction
                and r["stride_slip"] == slip
                and r["final"]
            ]
            if not got:
                cells.append("—")
                continue
            errors = [r["final"]["mae_m"] for r in got]
            ratios = [r["final"]["mae_m"] / supervised[r["seed"]]["mae_m"] for r in got]
            cells.append(f"{mean_sd(errors, 3)} m ({statistics.fmean(ratios):.2f}×)")
        lines.append(f"| {fraction:.0%} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _pct(scores: dict | None) -> str:
    """A held-out total error, or — where the run has no such eval."""
    return "—" if not scores else f"{scores['total_pct']:.2f}"


def growth_table(results: dict) -> str:
    lines = [
        "| seed | online error before (%) | peak after (%) | at the end (%) | presentations to "
        f"recover (≤ {RECOVERED}× before) | held-out before (%) | held-out after (%) |",
        "|---|---|---|---|---|---|---|",
    ]
    for g in results["growth"]:
        o = g["online"]
        recovered = o["presentations_to_recover"]
        lines.append(
            f"| {g['seed']} | {o['before_pct']:.2f} | {o['peak_pct']:.2f} | {o['end_pct']:.2f} | "
            f"{'not within the run' if recovered is None else recovered} | "
            f"{_pct(g['before'])} | {_pct(g['final'])} |"
        )
    return "\n".join(lines)


def recovery_figure(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    for g in results["growth"]:
        curve = g["online"]["curve"]
        p, e = np.array(curve["presentation"]), np.array(curve["error_pct"])
        if e.size >= ROLLING:
            smooth = np.convolve(e, np.ones(ROLLING) / ROLLING, mode="valid")
            ax.plot(p[ROLLING - 1 :], smooth, label=f"seed {g['seed']}")
        ax.axvline(g["growth_presentation"], color="grey", linestyle="--", linewidth=0.8)
    ax.set_xlabel("presentation")
    ax.set_ylabel(f"online error, body units (%, mean of {ROLLING})")
    ax.set_title(f"stride × {GROWTH_FACTOR:g} at the dashed line; nominal stride unchanged")
    if ax.get_legend_handles_labels()[0]:
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.embodied", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("sources", nargs="+", help="finished supervised runs (or their folders)")
    parser.add_argument("--out", required=True, help="folder for embodied.json and the figure")
    parser.add_argument(
        "--cache", default=None, help="keep each source's replays here, for later calls to reuse"
    )
    args = parser.parse_args(argv)
    try:
        sources = find_sources(args.sources)
        header(
            "embodied",
            f"{REPLAYS} replays of each of {len(sources)} supervised run"
            + "s" * (len(sources) != 1)
            + ": the walk fraction × stride slip table and the growth spurt",
            cache=Path(args.cache).resolve() if args.cache else None,
            output=Path(args.out).resolve(),
        )
        bar = progress(total=REPLAYS * len(sources), desc="replays", unit="replay")
        results = study(sources, cache=Path(args.cache) if args.cache else None, bar=bar)
        bar.close()
    except (ReplayError, FileNotFoundError, ValueError) as exc:
        print(f"embodied: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "embodied.json").write_text(json.dumps(results, indent=2) + "\n")
    recovery_figure(results, out / "growth_recovery.png")
    report = report_text(results, argv if argv is not None else sys.argv[1:])
    (out / "README.md").write_text(report)
    print(report)
    footer("embodied", ["embodied.json", "growth_recovery.png", "README.md"], out)
    return 0


def report_text(results: dict, argv: Sequence[str]) -> str:
    """The results page: both tables, the figure, and the commands behind them."""
    sources = sorted({r["source"] for r in results["rows"]})
    return "\n".join(
        [
            "# Distance from the robot's own body: results",
            "",
            "Written by `python -m parallax.tools.analysis.embodied "
            + " ".join(argv)
            + "` from the supervised runs",
            *[f"- `{s}`" for s in sources],
            "",
            "each trained by `parallax-train experiment=recipe_multi_5_20_weighted seed=N` and "
            "evaluated by `parallax-eval RUN` and `parallax-eval RUN --checkpoint "
            "checkpoint_before_perturbation.pt --out RUN/eval_before`. Every cell is "
            "`parallax-replay RUN` with the overrides in embodied.json. What the odometry "
            "learner is scored against is the slip-free walk to touch (docs/embodied.md).",
            "",
            "## Walk fraction × stride slip (the models at the end of the run)",
            "",
            table(results),
            "",
            f"## Growth spurt (stride × {GROWTH_FACTOR:g} at {GROWTH_START_FRACTION:.0%} of the "
            "run)",
            "",
            "Errors in body units: the estimate against the strides the grown body needs, "
            "× the nominal stride. Held-out before: the model at §5's perturbation (before the "
            "spurt; — where the run has no eval of it); after: at the end.",
            "",
            growth_table(results),
            "",
            "![online error around the spurt](growth_recovery.png)",
            "",
        ]
    )


if __name__ == "__main__":
    sys.exit(main())
