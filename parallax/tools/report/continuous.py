"""The report of the continuous sweep (beyond the paper's pick-and-place, §4.1; docs/continuous.md),
beside the recipe's pick-and-place 5–20 cm weighted runs before their perturbation.

From the evaluations (parallax-eval, held-out photographs) of:

- RUNS: ``experiment=continuous_multi_5_20_weighted`` for several seeds;
- ``--pairing``: the same with ``coder.pairing=consecutive``;
- ``--speeds``: the same at other ``env.sweep.speed_m``;
- ``--recipe``: the recipe's runs, whose ``recipe_multi_5_20_weighted`` models were evaluated
  before their perturbation (RUN/eval_before);
- ``--recipe-last``: the same runs replayed with each trial's last pan as the distance readout
  (``train.distance_readout=last``, the sweep's: the replays of ``without_best_readout``), so
  that the sweep is also compared with pick-and-place read out the same way;

it writes six tables: the eye's error at the body offsets of L (Table 2's form); the distance
error per range with the iterations a presentation takes; the sweep against pick-and-place as
paired differences on the seeds both have and the same photographs, with 95 % intervals
(parallax.tools.report.paired); the two pairings; the error against
body speed; and the error against lateral travel when the sweep stops early
(:mod:`parallax.tools.analysis.continuous`). Mean ± standard deviation over seeds.

    python -m parallax.tools.report.continuous RUNS --pairing DIR --speeds DIR --recipe DIR
        [--recipe-last DIR] [--json FILE] [--markdown FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from parallax.config import load_run_config
from parallax.envs.sweep import fastest_target_pan_deg, sweep_iterations
from parallax.tools.analysis.continuous import analyse, eye_error_parts
from parallax.tools.report.groups import Stat
from parallax.tools.report.paired import paired_difference, seed_means, seeds_needed
from parallax.tools.report.runs import EVAL_NAME, METRICS_NAME, read_record, record_file
from parallax.writable import file_problem

RANGES = ("3-4.9", "5-6.9", "7-10", "total")
EYE_PARTS = ("eye_mae_deg", "eye_unlearnable_deg")
RECIPE = "recipe_multi_5_20_weighted"
#: The rows of the distance table: the sweep (each trial's last pan, its readout) and
#: pick-and-place read out as the recipe does (the best-encoded pan) and as the sweep does.
MOTIONS = {
    "continuous": "continuous (last pan)",
    "pick_and_place": "pick-and-place (best-encoded pan)",
    "pick_and_place_last": "pick-and-place (last pan, replayed)",
}
#: The share of a run's last presentations whose online pursuit figures are averaged.
LAST_SHARE = 0.1


def _evaluated(folder: Path, eval_name: str = "", depth: str = "*") -> list[dict]:
    """Every run ``depth`` below ``folder`` with an evaluation (RUN/[eval_name/]eval.json): the
    eval, the run's config and its last presentations' pursuit figures, ordered by seed."""
    found = []
    for summary in sorted(folder.glob(f"{depth}/summary.json")):
        run = summary.parent
        path = run / eval_name / EVAL_NAME
        if record_file(path) is None:
            continue
        cfg = load_run_config(run)
        found.append({"run": run, "cfg": cfg, "eval": json.loads(read_record(path))})
    return sorted(found, key=lambda item: int(item["cfg"].seed))


def _online_motion(run: Path) -> dict[str, float]:
    """Mean tracking error and retinal slip (deg) over the run's last presentations."""
    lines = [json.loads(line) for line in read_record(run / METRICS_NAME).splitlines()]
    last = lines[-max(1, int(len(lines) * LAST_SHARE)) :]
    keys = ("tracking_error_deg", "retinal_slip_deg")
    return {k: float(np.mean([line[k] for line in last])) for k in keys if k in last[0]}


def _spread(values) -> dict:
    """Mean, sd and count over seeds, as the paper tables' cells are stored."""
    return Stat.of(values).as_dict()


def _text(cell: dict, digits: int = 2) -> str:
    """A stored cell as the tables print it: '0.21 ± 0.03', the mean alone for one seed."""
    return Stat.from_dict(cell).text(digits)


def _iterations(cfg) -> int:
    """Iterations (eye movements) a presentation takes."""
    lateral = [float(l) for l in cfg.curriculum.lateral_positions]
    if cfg.env.motion == "continuous":
        return sweep_iterations(lateral[-1], float(cfg.env.sweep.speed_m))
    return len(lateral) * int(cfg.env.trial_length)


def _recipe_runs(folder: Path | None) -> list[dict]:
    if folder is None:
        return []
    # a run of the folder, or a replay of it (parallax-replay writes RUN/<overrides>/)
    runs = _evaluated(folder, "eval_before") + _evaluated(folder, "eval_before", "*/*")
    return [
        r
        for r in runs
        if any(p.name.startswith(f"experiment={RECIPE},") for p in (r["run"], r["run"].parent))
    ]


def paired_against(sweeps: list[dict], picks: list[dict]) -> dict:
    """The sweep's distance error minus pick-and-place's, per grid distance (the same held-out
    photograph at each), on the seeds both have: the paired difference and its interval."""
    by_seed = {int(r["cfg"].seed): r for r in picks}
    a, b, seeds = [], [], []
    for sweep in sweeps:
        pick = by_seed.get(int(sweep["cfg"].seed))
        if pick is None:
            continue
        mine, theirs = (r["eval"]["distance"]["per_distance"] for r in (sweep, pick))
        common = [d for d in mine if d in theirs]
        a.append([mine[d] for d in common])
        b.append([theirs[d] for d in common])
        seeds.append(int(sweep["cfg"].seed))
    difference = paired_difference(a, b)
    return {
        **difference.as_dict(),
        "verdict": difference.verdict,
        "seed_list": seeds,
        "seeds_needed": seeds_needed(seed_means(a, b), difference),
    }


def build(
    runs: Path, pairing: Path, speeds: Path, recipe: Path, recipe_last: Path | None = None
) -> dict:
    sweeps = _evaluated(runs)
    if not sweeps:
        raise FileNotFoundError(f"{runs}: no evaluated run (parallax-eval RUN first)")
    picks = _recipe_runs(recipe)
    picks_last = _recipe_runs(recipe_last)
    labels = list(sweeps[0]["eval"]["mae_per_position"]["greedy"])
    tracking = {
        label: {
            "continuous": _spread(r["eval"]["mae_per_position"]["greedy"][label] for r in sweeps),
            "pick_and_place": _spread(
                r["eval"]["mae_per_position"]["greedy"][label] for r in picks
            ),
        }
        for label in labels
    }

    def distance(items) -> dict:
        parts = [
            eye_error_parts(r["eval"], [float(l) for l in r["cfg"].curriculum.lateral_positions])
            for r in items
        ]
        return {
            **{k: _spread(r["eval"]["distance"]["by_range"][k] for r in items) for k in RANGES},
            **{k: _spread(part[k] for part in parts) for k in EYE_PARTS},
        }

    compared = {
        "continuous": {
            **distance(sweeps),
            "iterations": _iterations(sweeps[0]["cfg"]),
            "training_iterations": int(sweeps[0]["eval"]["presentations"])
            * _iterations(sweeps[0]["cfg"]),
        },
        **{
            name: {
                **distance(items),
                "iterations": _iterations(items[0]["cfg"]) if items else None,
                "training_iterations": (
                    int(items[0]["eval"]["presentations"]) * _iterations(items[0]["cfg"])
                    if items
                    else None
                ),
            }
            for name, items in (("pick_and_place", picks), ("pick_and_place_last", picks_last))
            if items
        },
    }
    paired = {
        name: paired_against(sweeps, items)
        for name, items in (("pick_and_place", picks), ("pick_and_place_last", picks_last))
        if items
    }
    seed0 = next(r for r in sweeps if int(r["cfg"].seed) == 0)

    def row(item) -> dict:
        cfg, result = item["cfg"], item["eval"]
        speed, profile = float(cfg.env.sweep.speed_m), str(cfg.env.sweep.profile)
        nearest = float(cfg.env.distances.start)
        return {
            "speed_m": speed,
            "iterations": _iterations(cfg),
            "target_turn_deg": fastest_target_pan_deg(speed, profile, nearest),
            "eye_mae_deg": float(result["mae"]["greedy"]),
            "distance_total": float(result["distance"]["by_range"]["total"]),
            **_online_motion(item["run"]),
        }

    pairings = {"reference": row(seed0)}
    for item in _evaluated(pairing):
        pairings[str(item["cfg"].coder.pairing)] = row(item)
    speed_rows = sorted(
        [row(seed0)] + [row(i) for i in _evaluated(speeds)], key=lambda r: r["speed_m"]
    )
    stops = [analyse(r["run"]) for r in sweeps]
    stopping = [
        {
            "rule": rows[0]["rule"],
            "travel_cm": _spread(row["travel_cm"] for row in rows),
            "total": _spread(row["total"] for row in rows),
        }
        for rows in zip(*(s["stopping"] for s in stops))
    ]
    readouts = {
        name: _spread(s["readouts"][name]["total"] for s in stops) for name in stops[0]["readouts"]
    }
    return {
        "runs": [str(r["run"]) for r in sweeps],
        "recipe_runs": [str(r["run"]) for r in picks],
        "recipe_last_runs": [str(r["run"]) for r in picks_last],
        "tracking": tracking,
        "distance": compared,
        "paired": paired,
        "pairing": pairings,
        "speed": speed_rows,
        "readouts": readouts,
        "stopping": stopping,
    }


def markdown(report: dict) -> str:
    out = [
        "# The continuous sweep against pick-and-place",
        "",
        f"Made by `python -m parallax.tools.report.continuous` from {len(report['runs'])} "
        f"continuous runs and {len(report['recipe_runs'])} recipe runs; held-out photographs, "
        "the greedy eye; mean ± sd over seeds.",
        "",
        "## The eye at the body offsets of L (°)",
        "",
        "| l (cm) | continuous sweep | pick-and-place (recipe, before its perturbation) |",
        "|---|---|---|",
    ]
    for label, cell in report["tracking"].items():
        out.append(
            f"| {label} | {_text(cell['continuous'], 3)} | {_text(cell['pick_and_place'], 3)} |"
        )
    out += [
        "",
        "## Distance error (%)",
        "",
        "| motion | 3-4.9 m | 5-6.9 m | 7-10 m | total | iterations a presentation | "
        "training iterations | eye (°) | of it, no function of d (°) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, cells in report["distance"].items():
        values = " | ".join(_text(cells[k]) for k in RANGES)
        eye = " | ".join(_text(cells[k], 3) for k in EYE_PARTS)
        out.append(
            f"| {MOTIONS.get(name, name)} | {values} | {cells['iterations']} | "
            f"{cells['training_iterations']} | {eye} |"
        )
    if report.get("paired"):
        out += [
            "",
            "## The sweep against pick-and-place, paired",
            "",
            "The sweep's distance error minus pick-and-place's (percentage points), per grid "
            "distance on the same held-out photograph, on the seeds both have; 95 % bootstrap "
            "interval over seeds and photographs.",
            "",
            "| against | seeds | difference | 95 % interval | verdict | seeds that would tell |",
            "|---|---|---|---|---|---|",
        ]
        for name, d in report["paired"].items():
            seeds = ", ".join(str(seed) for seed in d["seed_list"])
            verdict = {"a lower": "the sweep is better", "a higher": "the sweep is worse"}.get(
                d["verdict"], d["verdict"]
            )
            out.append(
                f"| {MOTIONS[name]} | {seeds} | {d['mean']:+.2f} | "
                f"[{d['low']:+.2f}, {d['high']:+.2f}] | {verdict} | "
                f"{d['seeds_needed'] if d['seeds_needed'] is not None else '—'} |"
            )
    out += [
        "",
        "## Which pairing learns to pursue (seed 0)",
        "",
        "| pairing | eye (°) | distance total (%) | tracking error in motion (°) | "
        "retinal slip (° an iteration) |",
        "|---|---|---|---|---|",
    ]
    for name, r in report["pairing"].items():
        out.append(
            f"| {name} | {r['eye_mae_deg']:.3f} | {r['distance_total']:.2f} | "
            f"{r.get('tracking_error_deg', math.nan):.3f} | "
            f"{r.get('retinal_slip_deg', math.nan):.4f} |"
        )
    out += [
        "",
        "## Error against body speed (seed 0, about 64,640 training iterations each)",
        "",
        "| speed (mm an iteration) | iterations a presentation | target's fastest turn at 3 m "
        "(°/iteration) | eye (°) | distance total (%) | tracking error in motion (°) |",
        "|---|---|---|---|---|---|",
    ]
    for r in report["speed"]:
        out.append(
            f"| {1000 * r['speed_m']:g} | {r['iterations']} | {r['target_turn_deg']:.3f} | "
            f"{r['eye_mae_deg']:.3f} | {r['distance_total']:.2f} | "
            f"{r.get('tracking_error_deg', math.nan):.3f} |"
        )
    out += [
        "",
        "## What to read from the pursuit: distance error (%) of a network fitted by 5-fold "
        "cross-validation",
        "",
        "| readout | total |",
        "|---|---|",
    ]
    for name, cell in report["readouts"].items():
        out.append(f"| {name} | {_text(cell)} |")
    out += [
        "",
        "## When to stop moving: error against lateral travel (the planner's estimate)",
        "",
        "| stop | lateral travel, out and back (cm) | distance total (%) |",
        "|---|---|---|",
    ]
    for r in report["stopping"]:
        out.append(f"| {r['rule']} | {_text(r['travel_cm'], 1)} | {_text(r['total'])} |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.continuous", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("runs", type=Path, help="the continuous runs (a sweep folder)")
    parser.add_argument("--pairing", type=Path, required=True)
    parser.add_argument("--speeds", type=Path, required=True)
    parser.add_argument("--recipe", type=Path, required=True)
    parser.add_argument(
        "--recipe-last",
        type=Path,
        default=None,
        help="the recipe's runs replayed with train.distance_readout=last",
    )
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--markdown", type=Path, default=None)
    args = parser.parse_args(argv)
    for path in (args.json, args.markdown):
        if path is not None and (why := file_problem(path)):
            print(f"continuous: error: {path} {why}", file=sys.stderr)
            sys.exit(2)
    try:
        report = build(args.runs, args.pairing, args.speeds, args.recipe, args.recipe_last)
    except (FileNotFoundError, ValueError, KeyError, StopIteration) as exc:
        print(f"continuous: error: {exc!r}", file=sys.stderr)
        sys.exit(2)
    text = markdown(report)
    print(text, end="")
    try:
        for path, content in (
            (args.json, json.dumps(report, indent=1, default=str) + "\n"),
            (args.markdown, text),
        ):
            if path is not None:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(content)
    except OSError as exc:
        print(f"continuous: error: cannot write: {exc}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
