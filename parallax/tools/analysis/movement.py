"""How far must the robot move? The movement planner (paper §7's first future work) on the eye
movements of finished runs.

Every trial starts from pan 0 at its own lateral position (§3.2), so a run that swept the whole
list L every presentation also shows what a robot that visited only some positions, in any
order, would have seen. This module gives the planner of :mod:`parallax.distance.planner` the
queue a finished run's distance learner ended with (its last c full sweeps, with the supervisor's
distances), then lets it choose, for each held-out presentation of the run's parallax-eval, where
to move and when to stop. It sees only the pans of the positions it visits. For each price it
reports the distance error against the eye movements (trials × t_h) and the lateral travel per
presentation. The fixed lists 5–10 and 5–20 cm are points on the same axes: the estimator of
their positions, and the run's own network (parallax-eval's error).

The eye here learnt from full sweeps; a robot that plans while it learns visits the far
positions less often, and its eye there may learn more slowly.

    python -m parallax.tools.analysis.movement RUN_OR_MULTIRUN… --out DIR
        [--prices 0 0.05 0.1 0.2 0.5 1] [--trained PLANNED_RUN_OR_MULTIRUN…]

``--trained``: runs trained with movement.route=planned, evaluated by parallax-eval: their
planned routes on held-out presentations, and their eye beside the sweeping runs' eye (the
last trials' MAE at each position, and the greedy held-out MAE per position).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from parallax import readouts
from parallax.config import load_run_config
from parallax.distance.planner import MovementPlanner
from parallax.metrics import position_label
from parallax.tools.evaluate import route_results
from parallax.tools.replay import ReplayError, find_sources, read_stream
from parallax.tools.report.groups import mean_sd
from parallax.tools.report.runs import read_record, record_file

PRICES = (0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
EVAL = "eval.json"


def planner_of(run_dir: Path, price_per_trial: float = 0.0) -> tuple[MovementPlanner, dict]:
    """A planner with the queue the run's distance learner ended with, and the run's config."""
    cfg = load_run_config(run_dir)
    lateral = [float(l) for l in cfg.curriculum.lateral_positions]
    planner = MovementPlanner(
        lateral, queue_size=int(cfg.distance.queue_size), price_per_trial=price_per_trial
    )
    key = readouts.of_run(cfg).key
    learnt = [r for r in read_stream(run_dir) if r["learnt_distance"] and r.get("route") is None]
    for record in learnt[-planner.queue_size :]:
        for s, d in zip(record[key], record["distances"]):
            planner.observe(s, d)
    return planner, cfg


def held_out(run_dir: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """The greedy eye's vectors s and distances of the run's parallax-eval, and the eval."""
    path = run_dir / EVAL  # or its compressed form
    if record_file(path) is None:
        raise ReplayError(f"{run_dir} has no {EVAL}: run parallax-eval on it first")
    result = json.loads(read_record(path))
    grid = result["greedy_samples"]["grid"]
    return np.asarray(grid["pans"], dtype=np.float64), np.asarray(grid["distances"]), result


def curve(run_dir: Path, prices: Sequence[float]) -> dict:
    """One run: the planner at each price, and the fixed lists, on its held-out presentations."""
    planner, cfg = planner_of(run_dir)
    pans, distances, evaluation = held_out(run_dir)
    trial_length = int(cfg.env.trial_length)
    lateral_cm = [100.0 * l for l in planner.lateral_positions]
    points = []
    for price in prices:
        planner.price_per_trial = float(price)
        point = route_results(planner, pans, distances, trial_length)
        point["error_pct"] = point["by_range"]["total"]
        point["first_positions_cm"] = sorted(
            {position_label(planner.lateral_positions[v[0]]) for v in point.pop("routes")}
        )
        points.append(point)
    fixed = {}
    for name, upto in (("5-10", 0.10), ("5-20", 0.20)):
        chosen = [k for k, l in enumerate(planner.lateral_positions) if l <= upto + 1e-9]
        if len(chosen) < 2:
            continue
        estimates = [planner.estimate(chosen, s[chosen]) for s in pans]
        fixed[name] = {
            "error_pct": float(np.mean(np.abs(np.array(estimates) - distances) / distances) * 100),
            "eye_movements": float(len(chosen) * trial_length),
            "travel_cm": 2 * max(lateral_cm[k] for k in chosen),
        }
    network = (evaluation.get("distance") or {}).get("by_range", {}).get("total")
    return {
        "source": str(run_dir),
        "seed": int(cfg.seed),
        "trials": int(distances.size),
        "queue": planner.queue_size,
        "planner": points,
        "fixed_estimator": fixed,
        "network_error_pct": network,
    }


def table(results: list[dict]) -> str:
    """Mean ± sd over runs: error, eye movements and travel per presentation at each price."""

    trials = sorted({r["trials"] for r in results})
    lines = [
        f"{len(results)} runs, {', '.join(map(str, trials))} held-out presentations each; "
        "mean ± sd over runs.",
        "",
        "| route | price per trial (points of %) | distance error (%) | eye movements | "
        "lateral travel (cm) |",
        "|---|---|---|---|---|",
    ]
    for i, point in enumerate(results[0]["planner"]):
        rows = [r["planner"][i] for r in results]
        lines.append(
            f"| planned | {point['price_per_trial']:g} | {mean_sd([p['error_pct'] for p in rows])} "
            f"| {mean_sd([p['eye_movements'] for p in rows], 0)} | "
            f"{mean_sd([p['travel_cm'] for p in rows], 0)} |"
        )
    for name in results[0]["fixed_estimator"]:
        rows = [r["fixed_estimator"][name] for r in results]
        lines.append(
            f"| fixed {name} cm, the planner's estimator | — | "
            f"{mean_sd([p['error_pct'] for p in rows])} | {rows[0]['eye_movements']:.0f} | "
            f"{rows[0]['travel_cm']:.0f} |"
        )
    networks = [r["network_error_pct"] for r in results if r["network_error_pct"] is not None]
    if networks:
        last = results[0]["fixed_estimator"].get("5-20", {})
        movements, travel = last.get("eye_movements", math.nan), last.get("travel_cm", math.nan)
        lines.append(
            f"| fixed 5-20 cm, the run's network (parallax-eval) | — | {mean_sd(networks)} | "
            f"{movements:.0f} | {travel:.0f} |"
        )
    return "\n".join(lines)


def trained(run_dir: Path) -> dict:
    """A run trained with planned routes: its held-out route block and its eye."""
    cfg = load_run_config(run_dir)
    _, _, evaluation = held_out(run_dir)
    if "route" not in evaluation:
        raise ReplayError(f"{run_dir / EVAL} has no planned route (movement.route=list?)")
    route = {k: v for k, v in evaluation["route"].items() if k != "routes"}
    return {
        "source": str(run_dir),
        "seed": int(cfg.seed),
        "price_per_trial": float(cfg.movement.price_per_trial),
        "explore": float(cfg.movement.explore),
        "route": route,
        "eye": _eye(run_dir, evaluation),
    }


def _eye(run_dir: Path, evaluation: dict) -> dict:
    summary = json.loads((run_dir / "summary.json").read_text())
    return {
        "last_trials_mae": {k: v["mean"] for k, v in summary["last_trials"].items()},
        "last_trials_count": {k: v["trials"] for k, v in summary["last_trials"].items()},
        "held_out_greedy_mae": evaluation["mae_per_position"]["greedy"],
    }


def trained_table(planned: list[dict], sweeping: list[dict]) -> str:
    """The trained planners' routes, and their eye per position beside the sweeping runs'."""

    lines = [
        "| price per trial | runs | held-out presentations | distance error (%) | "
        "eye movements | lateral travel (cm) |",
        "|---|---|---|---|---|---|",
    ]
    for price in sorted({r["price_per_trial"] for r in planned}):
        rows = [r["route"] for r in planned if r["price_per_trial"] == price]
        lines.append(
            f"| {price:g} | {len(rows)} | {rows[0]['presentations']} | "
            f"{mean_sd([r['by_range']['total'] for r in rows])} | "
            f"{mean_sd([r['eye_movements'] for r in rows], 0)} | "
            f"{mean_sd([r['travel_cm'] for r in rows], 0)} |"
        )
    labels = list(planned[0]["eye"]["last_trials_mae"])
    lines += [
        "",
        "Eye-movement MAE (°) per lateral position (cm), mean over runs: the last 100 trials "
        "of training at that position, and the greedy eye on the held-out presentations.",
        "",
        "| | " + " | ".join(labels) + " |",
        "|---|" + "---|" * len(labels),
    ]
    for name, runs in (("planned", planned), ("sweeping", sweeping)):
        if not runs:
            continue
        last = [statistics.fmean(r["eye"]["last_trials_mae"][k] for r in runs) for k in labels]
        held = [statistics.fmean(r["eye"]["held_out_greedy_mae"][k] for r in runs) for k in labels]
        lines.append(f"| {name}, training | " + " | ".join(f"{v:.3f}" for v in last) + " |")
        lines.append(f"| {name}, held-out | " + " | ".join(f"{v:.3f}" for v in held) + " |")
    return "\n".join(lines)


def target_lines(planned: list[dict], sweeping_results: list[dict]) -> list[str]:
    """The planned runs' own routes against the fixed 5–20 cm list's network, as measured."""
    networks = [
        r["network_error_pct"] for r in sweeping_results if r["network_error_pct"] is not None
    ]
    fixed = sweeping_results[0]["fixed_estimator"].get("5-20") if sweeping_results else None
    if not networks or fixed is None or not planned:
        return []
    error = statistics.fmean(r["route"]["by_range"]["total"] for r in planned)
    movements = statistics.fmean(r["route"]["eye_movements"] for r in planned)
    network = statistics.fmean(networks)
    return [
        f"Planned while learning, its own routes: {error:.2f} % distance error with "
        f"{movements:.0f} eye movements per presentation, {movements / fixed['eye_movements']:.0%} "
        f"of the fixed 5-20 cm list's {fixed['eye_movements']:.0f}; the fixed list's network: "
        f"{network:.2f} % (means over runs).",
    ]


def report_text(
    results: list[dict],
    planned: list[dict],
    planned_curves: list[dict],
    sweeping: list[dict],
    argv,
) -> str:
    sources = [r["source"] for r in results]
    parts = [
        "# The robot decides how far to move: results",
        "",
        "Written by `python -m parallax.tools.analysis.movement " + " ".join(argv) + "`.",
        "",
        "## The planner on the eye of runs that swept all of L",
        "",
        "Runs trained by `parallax-train experiment=recipe_multi_5_20_weighted seed=N` and "
        "evaluated by `parallax-eval RUN` (held-out photographs, the full grid):",
        *[f"- `{s}`" for s in sources],
        "",
        table(results),
        "",
        "![distance error against movement](error_vs_movement.png)",
        "![positions visited by distance](stops_by_distance.png)",
    ]
    if planned:
        parts += [
            "",
            "## Robots that planned while they learnt",
            "",
            "Runs trained by `parallax-train experiment=planned_multi_5_20_weighted seed=N` "
            "and evaluated by `parallax-eval RUN`:",
            *[f"- `{r['source']}`" for r in planned],
            "",
            "Their own routes on the held-out presentations (parallax-eval), at the price they "
            "learnt with:",
            "",
            trained_table(planned, sweeping),
            "",
            *target_lines(planned, results),
            "",
            "Their eye and their planner's queue at every price, on the same held-out "
            "presentations (the curve; the fixed lists as points):",
            "",
            table(planned_curves),
        ]
    return "\n".join(parts) + "\n"


def figures(
    results: list[dict], out: Path, planned_curves: Sequence[dict] = (), planned=()
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for axis, key, label in (
        (axes[0], "eye_movements", "eye movements per presentation"),
        (axes[1], "travel_cm", "lateral travel per presentation (cm)"),
    ):
        for r in results:
            xs = [p[key] for p in r["planner"]]
            ys = [p["error_pct"] for p in r["planner"]]
            axis.plot(xs, ys, marker="o", label=f"planned, seed {r['seed']}")
            for name, point in r["fixed_estimator"].items():
                axis.scatter(point[key], point["error_pct"], marker="s", color="k")
                axis.annotate(f"fixed {name} cm", (point[key], point["error_pct"]), fontsize=7)
        for r in planned_curves:
            xs = [p[key] for p in r["planner"]]
            ys = [p["error_pct"] for p in r["planner"]]
            axis.plot(
                xs,
                ys,
                marker=".",
                linestyle="--",
                label=f"planned while learning, seed {r['seed']}",
            )
        for r in planned:
            axis.scatter(
                r["route"][key], r["route"]["by_range"]["total"], marker="*", s=90, zorder=3
            )
        axis.set_xlabel(label)
        axis.set_ylabel("distance error (%)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "error_vs_movement.png", dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    for r in results:
        for point in r["planner"]:
            if point["price_per_trial"] not in (0.05, 0.2):
                continue
            by = point["trials_by_distance"]
            ax.plot(
                [float(d) for d in by],
                list(by.values()),
                label=f"price {point['price_per_trial']:g}, seed {r['seed']}",
            )
    for r in planned:
        by = r["route"]["trials_by_distance"]
        ax.plot(
            [float(d) for d in by],
            list(by.values()),
            linestyle="--",
            label=f"planned while learning (price {r['price_per_trial']:g}), seed {r['seed']}",
        )
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("positions visited before stopping")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "stops_by_distance.png", dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.movement", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("sources", nargs="+", help="finished runs with parallax-eval results")
    parser.add_argument("--out", required=True, help="folder for movement.json and figures")
    parser.add_argument("--prices", nargs="+", type=float, default=list(PRICES))
    parser.add_argument("--trained", nargs="*", default=[], help="runs trained with planning")
    args = parser.parse_args(argv)
    try:
        sources = find_sources(args.sources)
        results = [curve(source, args.prices) for source in sources]
        trained_runs = find_sources(args.trained) if args.trained else []
        planned = [trained(run) for run in trained_runs]
        planned_curves = [curve(run, args.prices) for run in trained_runs]
        sweeping = [{"eye": _eye(s, held_out(s)[2])} for s in sources] if planned else []
    except (ReplayError, FileNotFoundError, ValueError) as exc:
        print(f"movement: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "movement.json").write_text(
        json.dumps(
            {"replayed": results, "trained": planned, "trained_curves": planned_curves}, indent=2
        )
        + "\n"
    )
    figures(results, out, planned_curves, planned)
    report = report_text(
        results, planned, planned_curves, sweeping, argv if argv is not None else sys.argv[1:]
    )
    (out / "README.md").write_text(report)
    print(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
