"""`python -m parallax.tools.bench.learning`: how long B robots in lockstep take to learn to pursue.

The eye has learnt (paper §4.2, Tables 2–3) when the eye-movement MAE |q_p − α*| (eq. 16) over
the last ``metrics.summary_trials`` trials of every lateral position is at most a threshold. For
each B and seed the benchmark trains a fresh run (the trainer's whole step: render, coder,
policy, dictionaries, distance learner) until the eye has learnt or a budget of robot-iterations
is spent, and reports the robot-iterations (environment steps × B) and the wall time it took.

The cases take turns, one presentation each per round, so that every B sees the same machine;
a case's wall time is the sum of its own presentations'. Medians over seeds.

Every trial counts: the cases read the trainer's own eye-movement tracker (an eye that only pursues
from pan 0 has not learnt). A recipe's N jittered presentations
(``train.start_jitter_presentations``) are lived through by B robots B times over; the benchmark
gives each B the same jittered experience per robot-iteration, ⌈N/B⌉ presentations. §5's
perturbation is off.

    python -m parallax.tools.bench.learning [--robots 1 4 16] [--seeds 0 1 2]
        [--threshold 0.3] [--budget 200000] [--json FILE] [OVERRIDES…]

OVERRIDES are Hydra overrides of every case (``experiment=recipe_single_5`` by default), e.g.
``experiment=recipe_multi_5_20_weighted --threshold 0.2`` or
``policy.robot_updates=mean coder.robot_updates=mean``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import torch

from parallax.config import compose
from parallax.tools.bench.timing import machine_name

if TYPE_CHECKING:
    from parallax.trainer import Trainer

DEFAULT_EXPERIMENT = "experiment=recipe_single_5"


@dataclass
class Case:
    """One B and seed: its trainer, whose eye-movement tracker holds every trial, the MAE window
    and threshold it must meet, and what it has spent."""

    robots: int
    seed: int
    trainer: Trainer
    window: int
    threshold: float
    robot_iterations: int = 0
    presentations: int = 0
    wall_s: float = 0.0
    learnt: bool = False
    worst_mae: float = math.nan  # over the last ``window`` trials, once every position has them

    def step(self) -> None:
        start = time.perf_counter()
        pres, _ = self.trainer.step_presentation(keep_view=False)
        self.wall_s += time.perf_counter() - start
        self.presentations += 1
        self.robot_iterations += pres.steps * self.robots
        cells = self.trainer.eye.last_trials(self.window).values()
        full = all(cell["trials"] >= self.window for cell in cells)
        worst = max(cell["mean"] for cell in cells)
        self.worst_mae = worst if full else math.nan
        self.learnt = full and worst <= self.threshold


def case_config(robots: int, seed: int, overrides: Sequence[str]):
    """The composed config of one case: the overrides at B robots, no perturbation, and the
    recipe's jittered presentations divided by B (rounded up)."""
    cfg = compose([*overrides, f"env.robots={robots}", f"seed={seed}", "perturbation=none"])
    jitter = cfg.train.start_jitter_presentations
    if jitter is not None:
        cfg.train.start_jitter_presentations = -(-int(jitter) // robots)
    return cfg


def run(
    robots: Sequence[int],
    seeds: Sequence[int],
    threshold: float,
    budget: int,
    overrides: Sequence[str],
    progress: bool = True,
) -> dict:
    from tqdm import tqdm

    from parallax.trainer import Trainer

    load_before = os.getloadavg()[0]
    with contextlib.ExitStack() as stack:
        cases = []
        for seed in seeds:
            for b in robots:
                cfg = case_config(b, seed, overrides)
                if int(cfg.train.threads) > 0:
                    torch.set_num_threads(int(cfg.train.threads))
                trainer = Trainer(cfg, stack.enter_context(tempfile.TemporaryDirectory()))
                stack.callback(trainer.exp.close)
                window = int(cfg.metrics.summary_trials)
                cases.append(Case(b, seed, trainer, window, threshold=threshold))
        bar = tqdm(
            total=len(cases),
            desc="cases learnt or out of budget",
            disable=not progress,
            mininterval=5.0,
        )
        running = list(cases)
        while running:
            for case in running:
                case.step()
            finished = [c for c in running if c.learnt or c.robot_iterations >= budget]
            running = [c for c in running if c not in finished]
            bar.update(len(finished))
            if progress and running:
                bar.set_postfix_str(
                    " ".join(
                        f"B={c.robots}/s{c.seed}:{c.worst_mae:.2f}°"
                        for c in running
                        if not math.isnan(c.worst_mae)
                    ),
                    refresh=False,
                )
        bar.close()
    device = cases[0].trainer.exp.coder.device if cases else torch.device("cpu")
    report: dict = {
        "overrides": list(overrides),
        # what the cases ran on, so that a saved report says which machine it measured
        "device": str(device),
        "device_name": machine_name(device),
        "threshold_deg": threshold,
        "budget_robot_iterations": budget,
        "load_average_before": load_before,
        "cores": os.cpu_count(),
        "torch": torch.__version__,
        "cases": [
            {
                "robots": c.robots,
                "seed": c.seed,
                "learnt": c.learnt,
                "robot_iterations": c.robot_iterations,
                "iterations_per_robot": c.robot_iterations // c.robots,
                "presentations": c.presentations,
                "wall_s": c.wall_s,
                "robot_iterations_per_second": c.robot_iterations / c.wall_s,
            }
            for c in cases
        ],
    }
    report["medians"] = medians(report["cases"], robots)
    return report


def medians(cases: list[dict], robots: Sequence[int]) -> dict:
    """Per B: medians over seeds, and their ratios to the first B's (a case out of budget counts
    as its budget, and the row says how many learnt)."""
    out: dict = {}
    for b in robots:
        mine = [c for c in cases if c["robots"] == b]
        out[f"B={b}"] = {
            "learnt": sum(c["learnt"] for c in mine),
            "seeds": len(mine),
            "robot_iterations": statistics.median(c["robot_iterations"] for c in mine),
            "wall_s": statistics.median(c["wall_s"] for c in mine),
            "robot_iterations_per_second": statistics.median(
                c["robot_iterations_per_second"] for c in mine
            ),
        }
    first = out[f"B={robots[0]}"]
    for row in out.values():
        row["robot_iterations_ratio"] = row["robot_iterations"] / first["robot_iterations"]
        row["wall_ratio"] = row["wall_s"] / first["wall_s"]
    return out


def format_report(report: dict) -> str:
    lines = [
        f"time to learn: eye-movement MAE ≤ {report['threshold_deg']:g}° at every position "
        f"({' '.join(report['overrides'])}); medians over seeds"
        + (f"; on {report['device_name']}" if report.get("device_name") else ""),
        f"{'':6} {'learnt':>7} {'robot-iterations':>17} {'ratio':>6} {'wall s':>8} {'ratio':>6} "
        f"{'robot-it/s':>10}",
    ]
    for b, row in report["medians"].items():
        lines.append(
            f"{b:<6} {row['learnt']:>3}/{row['seeds']:<3} {row['robot_iterations']:>17.0f} "
            f"{row['robot_iterations_ratio']:>6.2f} {row['wall_s']:>8.1f} "
            f"{row['wall_ratio']:>6.2f} {row['robot_iterations_per_second']:>10.1f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.bench.learning", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 4, 16], help="B values")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--threshold", type=float, default=0.3, help="MAE target, degrees")
    parser.add_argument(
        "--budget", type=int, default=200_000, help="robot-iterations before a case gives up"
    )
    parser.add_argument("--json", default=None, help="also write the report to this file")
    parser.add_argument("--show", default=None, metavar="JSON", help="print a written report")
    parser.add_argument(
        "overrides", nargs="*", help=f"Hydra overrides (default {DEFAULT_EXPERIMENT})"
    )
    args = parser.parse_args(argv)
    if args.show:
        print(format_report(json.loads(Path(args.show).read_text())))
        return
    prog = parser.prog
    for name, values in (("--robots", args.robots), ("--seeds", args.seeds)):
        if min(values) < (1 if name == "--robots" else 0):
            print(
                f"{prog}: error: {name}={values} must be ≥ {int(name == '--robots')}",
                file=sys.stderr,
            )
            sys.exit(2)
    if not (math.isfinite(args.threshold) and args.threshold > 0):
        print(f"{prog}: error: --threshold={args.threshold} must be > 0", file=sys.stderr)
        sys.exit(2)
    if args.budget < 1:
        print(f"{prog}: error: --budget={args.budget} must be ≥ 1", file=sys.stderr)
        sys.exit(2)
    overrides = args.overrides or [DEFAULT_EXPERIMENT]
    from parallax.config.overrides import composition_error

    error = composition_error([*overrides, "perturbation=none"], check=True)
    if error:
        print(f"{prog}: error: {error}", file=sys.stderr)
        sys.exit(2)
    robots = list(dict.fromkeys(args.robots))
    report = run(robots, list(dict.fromkeys(args.seeds)), args.threshold, args.budget, overrides)
    print(format_report(report))
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
