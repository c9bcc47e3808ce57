"""When does the input weighting of paper §3.5.1 (eqs. 10–12) help? A controlled test.

The paper weighs the rows of S that come from sensitive lateral positions (15–20 cm of
L = 5…20 cm: their disparity score at 3 m reaches the effective patch size) by
w_k = 1/((1 + l_r − l_k)·y), because "generating eye movement at those positions is more
difficult": their pans are the unreliable ones. Tables 4–5 show the weighting helping. Our own
5–20 cm eye is as accurate at the sensitive positions as elsewhere, and there the weighting does
not help (docs/results/README.md, docs/improvements.md).

This module separates the two by feeding the distance learner (`DistanceLearner`, the same
queue, scaling, network and Levenberg–Marquardt as training) pans made by the geometry,
q = atan(l/d) (`parallax.tools.analysis.synthetic_pans`), with noise of a known shape:

- ``uniform``: N(0, 0.05°) at every position;
- ``sensitive_x3``: N(0, 0.05°), but N(0, 0.15°) at the sensitive positions;
- ``sensitive_tail``: N(0, 0.05°) everywhere, and 10 % of the sensitive pans off by a further
  N(0, 1°), like the runaway pursuits of a large lateral step (paper Fig. 7).

Each (pattern, weighting, seed) streams vectors s with distances drawn from the paper's grid
(3.0…10.0 m) through the learner, then scores it on fresh noisy pans at every grid distance:
the mean of |d̂ − d|/d in %, as Tables 4–5. A seed fixes both the data and the network's
initialisation, so the weightings of one seed see the same vectors (a paired comparison).

    python -m parallax.tools.analysis.weighting_study [--patterns uniform sensitive_x3]
        [--y 0.1 1 5] [--seeds 4] [--jobs 2] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass

import numpy as np
import torch

from parallax.distance.learner import DistanceLearner
from parallax.tools import console
from parallax.tools.analysis.synthetic_pans import (
    PAPER_DISTANCES_M,
    PAPER_LATERAL_POSITIONS_M,
    parallax_pans,
)

NO_WEIGHTING = "none"


@dataclass(frozen=True)
class NoisePattern:
    """Pan noise in degrees: N(0, sigma) per position, sensitive_sigma at the sensitive ones,
    plus N(0, tail_sigma) on a fraction tail_probability of the sensitive pans."""

    sigma_deg: float
    sensitive_sigma_deg: float
    tail_probability: float = 0.0
    tail_sigma_deg: float = 0.0


NOISE_PATTERNS = {
    "uniform": NoisePattern(0.05, 0.05),
    "sensitive_x3": NoisePattern(0.05, 0.15),
    "sensitive_tail": NoisePattern(0.05, 0.05, tail_probability=0.1, tail_sigma_deg=1.0),
}


@dataclass(frozen=True)
class StudySettings:
    """The learner's settings (defaults: those of `launch/reproduce.sh`'s 5–20 cm runs) and the
    stream's length: ``stream`` vectors, so stream − queue + 1 fits."""

    stream: int = 200
    queue: int = 100
    weight_decay: float = 0.1
    test_repeats: int = 10

    def __post_init__(self) -> None:
        for name in ("stream", "queue", "test_repeats"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if self.stream < self.queue:
            raise ValueError(
                f"stream ({self.stream!r}) must be at least the queue size ({self.queue!r}): "
                "the learner fits only once its queue is full"
            )
        if not math.isfinite(self.weight_decay) or self.weight_decay < 0:
            raise ValueError(f"weight_decay must be a finite number ≥ 0, got {self.weight_decay!r}")


def noisy_pans(
    pattern: NoisePattern,
    distances_m: np.ndarray,
    sensitive: Sequence[bool],
    rng: np.random.Generator,
    lateral_positions_m: Sequence[float] = PAPER_LATERAL_POSITIONS_M,
) -> np.ndarray:
    """(n, r) pans in degrees: the parallax angle plus the pattern's noise."""
    flags = np.asarray(sensitive, dtype=bool)
    sigma = np.where(flags, pattern.sensitive_sigma_deg, pattern.sigma_deg)
    pans = parallax_pans(lateral_positions_m, distances_m, sigma, rng)
    if pattern.tail_probability > 0:
        tail = (rng.random(pans.shape) < pattern.tail_probability) & flags[None, :]
        pans = pans + np.where(tail, rng.normal(0.0, pattern.tail_sigma_deg, pans.shape), 0.0)
    return pans


def learner_error(
    pattern: NoisePattern, y: float | None, seed: int, settings: StudySettings = StudySettings()
) -> float:
    """Mean relative distance error (%) of one learner; ``y`` None: without weighting."""
    learner = DistanceLearner(
        PAPER_LATERAL_POSITIONS_M,
        queue_size=settings.queue,
        weighting=y is not None,
        y=1.0 if y is None else float(y),
        seed=int(seed),
        lm={"weight_decay": settings.weight_decay},
    )
    rng = np.random.default_rng(int(seed))
    distances = rng.choice(PAPER_DISTANCES_M, size=settings.stream)
    pans = noisy_pans(pattern, distances, learner.sensitive, rng)
    for s, distance in zip(pans, distances):
        learner.observe(s, float(distance))
    test_distances = np.repeat(PAPER_DISTANCES_M, settings.test_repeats)
    test_pans = noisy_pans(pattern, test_distances, learner.sensitive, rng)
    estimates = learner.predict(test_pans)
    return float(np.mean(np.abs(estimates - test_distances) / test_distances) * 100.0)


def _one(job: tuple[str, float | None, int, StudySettings]) -> dict[str, object]:
    name, y, seed, settings = job
    return {
        "pattern": name,
        "weighting": NO_WEIGHTING if y is None else f"y={y:g}",
        "seed": seed,
        "error_pct": learner_error(NOISE_PATTERNS[name], y, seed, settings),
    }


def run_study(
    patterns: Sequence[str],
    ys: Sequence[float],
    seeds: Iterable[int],
    settings: StudySettings = StudySettings(),
    jobs: int = 1,
    progress: bool = False,
) -> list[dict[str, object]]:
    """One row per (pattern, weighting, seed): its error in %. Same inputs, same rows."""
    check(patterns, ys, jobs)
    work = [
        (name, y, int(seed), settings) for name in patterns for y in [None, *ys] for seed in seeds
    ]
    bar = {"total": len(work), "disable": not progress, "desc": "learners", "unit": "fit"}
    if jobs == 1:
        return list(console.progress(map(_one, work), **bar))
    # One torch thread per worker: the jobs already fill the cores, and the fits are small.
    with ProcessPoolExecutor(
        max_workers=jobs, initializer=torch.set_num_threads, initargs=(1,)
    ) as pool:
        return list(console.progress(pool.map(_one, work), **bar))


def check(patterns: Sequence[str], ys: Sequence[float], jobs: int) -> None:
    """ValueError naming the first setting of a study that cannot run."""
    unknown = [name for name in patterns if name not in NOISE_PATTERNS]
    if unknown:
        raise ValueError(
            f"unknown noise pattern {unknown[0]!r}; choose from {sorted(NOISE_PATTERNS)}"
        )
    bad_y = [y for y in ys if not (math.isfinite(y) and y > 0)]
    if bad_y:
        raise ValueError(
            f"weighting hyper-parameter y must be positive and finite, got {bad_y[0]!r}"
        )
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs!r}")


def summarise(rows: Sequence[dict[str, object]]) -> list[dict[str, object]]:
    """Per (pattern, weighting): mean and sd over seeds, and against no weighting the mean paired
    difference (negative: the weighting helps) and on how many seeds it helps."""
    by_cell: dict[tuple[str, str], dict[int, float]] = {}
    for row in rows:
        by_cell.setdefault((str(row["pattern"]), str(row["weighting"])), {})[int(row["seed"])] = (
            float(row["error_pct"])
        )
    summary = []
    for (pattern, weighting), errors in by_cell.items():
        values = list(errors.values())
        baseline = by_cell.get((pattern, NO_WEIGHTING), {})
        paired = [errors[seed] - baseline[seed] for seed in errors if seed in baseline]
        summary.append(
            {
                "pattern": pattern,
                "weighting": weighting,
                "n": len(values),
                "mean_pct": statistics.fmean(values),
                "sd_pct": statistics.stdev(values) if len(values) > 1 else math.nan,
                "minus_none_pct": statistics.fmean(paired) if paired else math.nan,
                "seeds_better_than_none": sum(d < 0 for d in paired),
            }
        )
    return summary


def markdown(summary: Sequence[dict[str, object]]) -> str:
    """A table: one row per pattern and weighting."""
    lines = [
        "| noise pattern | weighting | distance error (mean ± sd over seeds) | against none "
        "(paired) "
        "| seeds where it helps |",
        "|---|---|---|---|---|",
    ]
    for cell in summary:
        against = (
            "" if cell["weighting"] == NO_WEIGHTING else f"{cell['minus_none_pct']:+.2f} points"
        )
        helps = (
            ""
            if cell["weighting"] == NO_WEIGHTING
            else f"{cell['seeds_better_than_none']} of {cell['n']}"
        )
        lines.append(
            f"| {cell['pattern']} | {cell['weighting']} | {cell['mean_pct']:.2f} ± "
            f"{cell['sd_pct']:.2f} % "
            f"| {against} | {helps} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.weighting_study",
        description=__doc__.split("\n\n")[0],
    )
    parser.add_argument(
        "--patterns",
        nargs="+",
        default=list(NOISE_PATTERNS),
        metavar="NAME",
        help=f"noise patterns, from {', '.join(NOISE_PATTERNS)} (default: all)",
    )
    parser.add_argument(
        "--y", nargs="+", type=float, default=[0.1, 1.0, 5.0], help="weighted learners' y"
    )
    parser.add_argument(
        "--seeds", type=int, default=4, help="seeds 0…N−1 (data and initialisation)"
    )
    parser.add_argument(
        "--stream", type=int, default=StudySettings.stream, help="vectors s streamed per learner"
    )
    parser.add_argument("--queue", type=int, default=StudySettings.queue, help="queue size c")
    parser.add_argument(
        "--weight-decay",
        type=float,
        default=StudySettings.weight_decay,
        help="distance.lm.weight_decay",
    )
    parser.add_argument("--jobs", type=int, default=1, help="learners fitted at once (processes)")
    parser.add_argument("--json", default=None, help="write the rows, summary and settings here")
    args = parser.parse_args(argv)
    try:
        if args.seeds < 1:
            raise ValueError(f"--seeds must be at least 1, got {args.seeds!r}")
        settings = StudySettings(
            stream=args.stream, queue=args.queue, weight_decay=args.weight_decay
        )
        check(args.patterns, args.y, args.jobs)  # before the header: bad input is one line
        learners = len(args.patterns) * (1 + len(args.y)) * args.seeds
        console.header(
            "weighting_study",
            f"{learners} distance learners on geometric pans with known noise",
            patterns=", ".join(args.patterns),
            y=", ".join(f"{y:g}" for y in args.y) + " (and no weighting)",
            seeds=args.seeds,
            jobs=args.jobs,
            output=os.path.abspath(args.json) if args.json else "the table, printed",
        )
        rows = run_study(
            args.patterns, args.y, range(args.seeds), settings, jobs=args.jobs, progress=True
        )
    except ValueError as error:
        print(f"weighting_study: {error}", file=sys.stderr)
        return 2
    summary = summarise(rows)
    print(markdown(summary))
    if args.json:
        payload = {
            "settings": asdict(settings),
            "patterns": {n: asdict(NOISE_PATTERNS[n]) for n in args.patterns},
            "y": args.y,
            "seeds": args.seeds,
            "rows": rows,
            "summary": summary,
        }
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(payload, handle, indent=1)
        console.footer("weighting_study", [args.json])
    return 0


if __name__ == "__main__":
    sys.exit(main())
