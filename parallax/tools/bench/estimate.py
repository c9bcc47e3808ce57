"""The wall time of a family's runs on this machine, from a `parallax-bench --processes` report.

    python -m parallax.tools.bench.estimate REPORT.json [FAMILY] [--seeds 3] [--headline-seeds 5]

For every experiment file of the family that `launch/reproduce.sh` trains (the ones it replays
from another's runs cost seconds; :mod:`parallax.tools.experiments`), one robot's
robot-iterations (train.presentations × the positions of L × t_h), times its seeds: the 5–20 cm
files, the headline rows, ``--headline-seeds``, the others ``--seeds``, as the script trains
them. The wall time is their sum over the machine-wide rate of the report's single-robot runs
side by side, the way the script runs them, for each code the report measured (this code, and a
revision given to ``--compare``). A curriculum in stages is counted at its final list.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

from parallax.config import compose
from parallax.tools.bench.timing import describe_machine
from parallax.tools.experiments import plan

#: The experiment files of a family: conf/experiment/<family>_*.yaml.
EXPERIMENTS = Path(__file__).resolve().parents[3] / "conf" / "experiment"


@functools.cache
def robot_iterations(name: str) -> int:
    """One run's robot-iterations of the experiment file ``name``."""
    cfg = compose([f"experiment={name}"])
    if cfg.env.motion == "continuous":  # one sweep of L per presentation
        from parallax.envs.sweep import sweep_iterations

        per_presentation = sweep_iterations(
            float(cfg.curriculum.lateral_positions[-1]), float(cfg.env.sweep.speed_m)
        )
    else:
        per_presentation = len(cfg.curriculum.lateral_positions) * int(cfg.env.trial_length)
    return int(cfg.train.presentations) * per_presentation * int(cfg.env.robots)


def trained(family: str) -> list[str]:
    """The family's experiment files that launch/reproduce.sh trains, in its order."""
    names = sorted(
        (path.stem for path in EXPERIMENTS.glob(f"{family}_*.yaml")),
        reverse=True,
    )
    names = [name for name in names if not name.endswith("_algorithm")]
    return [entry.name for entry in plan(names) if entry.source is None]


def estimate(report: dict, family: str, seeds: int, headline_seeds: int) -> list[str]:
    """The lines printed: the runs, their robot-iterations and the wall time per code."""
    runs = {name: headline_seeds if "multi_5_20" in name else seeds for name in trained(family)}
    if not runs:
        raise ValueError(f"no experiment files conf/experiment/{family}_*.yaml to train")
    total = sum(robot_iterations(name) * count for name, count in runs.items())
    lines = [
        f"{family}: {sum(runs.values())} runs of {len(runs)} experiment files, "
        f"{total / 1e6:.2f} million robot-iterations"
    ]
    for code, cases in report.get("processes", {}).items():
        rate = cases["two"]["steps_per_second"]
        lines.append(
            f"  {code}: {cases['two']['processes']} runs side by side at {rate:.1f} "
            f"robot-iterations/s in all → {total / rate / 3600:.1f} hours"
        )
    if len(lines) == 1:
        lines.append("  (the report has no --processes cases: no rate to estimate with)")
    else:  # a rate holds for the machine it was measured on, and under its load
        lines.append(f"  the rates {describe_machine(report)}")
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.bench.estimate", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("report", help="a parallax-bench --processes --json report")
    parser.add_argument("family", nargs="?", default="paper", help="experiment family")
    parser.add_argument("--seeds", type=int, default=3, help="seeds of each file")
    parser.add_argument("--headline-seeds", type=int, default=5, help="seeds of each 5–20 cm file")
    args = parser.parse_args(argv)
    try:
        report = json.loads(Path(args.report).read_text())
        lines = estimate(report, args.family, args.seeds, args.headline_seeds)
    except (OSError, ValueError) as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        sys.exit(2)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
