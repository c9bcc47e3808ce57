"""One presentation's record: its line of metrics.jsonl and its TensorBoard scalars.

:class:`parallax.trainer.Trainer` builds a :class:`PresentationRecord` after each presentation
and asks it for :meth:`~PresentationRecord.to_json` (the line of metrics.jsonl, read back by
parallax-replay, the analysis tools and :mod:`parallax.health`) and for
:meth:`~PresentationRecord.scalars` (what TensorBoard shows of it). The line's keys and their
order are part of the run's files: a committed run's metrics.jsonl is compared byte for byte.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np


@dataclass
class Walks:
    """With distance.targets=odometry: each robot's strides to the panel (None: it did not
    walk), the slip-free count, the odometry's error in % and the body's true stride."""

    walk_strides: list
    reach_strides: list
    odometry_error_pct: list
    true_stride_m: float

    def to_json(self) -> dict:
        return asdict(self)  # the fields, in their order, are the line's keys

    def scalars(self) -> Iterator[tuple[str, float]]:
        counted = [n for n in self.walk_strides if n is not None]
        yield "walk/walks", len(counted)
        yield "walk/true_stride_m", self.true_stride_m
        if counted:
            yield "walk/strides", float(np.mean(counted))
            errors = [e for e in self.odometry_error_pct if e is not None]
            yield "walk/odometry_error_pct", float(np.mean(errors))


@dataclass
class Route:
    """With movement.route=planned: where the robot went (indices into L; None: a sweep), how
    many trials and how far, the planner's estimate when it was scored (None: not scored, and
    no key in the line) and the planned routes' distance error per range."""

    route: list[int] | None
    trials: int
    travel_cm: float
    route_distance_error: dict
    estimate: float | None = None

    def to_json(self) -> dict:
        line: dict = {"route": self.route, "trials": self.trials, "travel_cm": self.travel_cm}
        if self.estimate is not None:
            line["route_estimate"] = self.estimate
        line["route_distance_error"] = self.route_distance_error
        return line

    def scalars(self) -> Iterator[tuple[str, float]]:
        yield "movement/sweep", float(self.route is None)
        yield "movement/trials", self.trials
        yield "movement/travel_cm", self.travel_cm
        for rng, v in self.route_distance_error.items():
            yield f"movement/route_error_pct_{rng}", v


@dataclass
class PresentationRecord:
    """What one presentation did, and the trainer's running metrics after it."""

    presentation: int
    steps: int
    stage: int
    perturbed: bool
    reward: float
    errors: Mapping[str, float]  # the coder's errors (eq. 4's eC, eF, ...): e_<k>
    policy_stats: Mapping[str, float]  # the policy's statistics: policy_<k>
    mae: float
    mae_per_position: dict
    mae_recent: float
    # Tables 2–3's window per position, for python -m parallax.tools.analysis.time_to_learn
    mae_recent_per_position: dict
    distance_error: dict
    # The eye-movement vectors s and their distances, exactly (JSON floats round-trip), so
    # parallax-replay can re-run the distance learner alone with another y, c or weighting.
    pans: list
    distances: list
    # s as each pan readout beyond the paper's reads it (parallax.readouts), by the readout's
    # key (best_pans: each trial's pan where the coder's reward peaked), for parallax-replay
    readouts: Mapping[str, list]
    # where each trial started (the paper: 0), and whether it was drawn from the jitter
    start_pans: list
    start_jitter: bool
    learnt_distance: bool
    walks: Walks | None  # None: the robots did not walk (or not this presentation)
    # env.motion=continuous: the pursuit during the sweep (parallax.presentation.Presentation.
    # motion: tracking_error_deg, retinal_slip_deg); None (and no key in the line) otherwise
    motion: Mapping[str, float] | None
    route: Route | None  # None: no planner
    distance_stats: Mapping[str, Any]  # the distance learner's last fit: lm_<k>

    def to_json(self) -> dict:
        """The line of metrics.jsonl (deterministic: no wall-clock values)."""
        return {
            "presentation": self.presentation,
            "steps": self.steps,
            "stage": self.stage,
            "perturbed": self.perturbed,
            "reward": self.reward,
            **{f"e_{k}": v for k, v in self.errors.items()},
            **{f"policy_{k}": v for k, v in self.policy_stats.items()},
            "mae": self.mae,
            "mae_per_position": self.mae_per_position,
            "mae_recent": self.mae_recent,
            "mae_recent_per_position": self.mae_recent_per_position,
            "distance_error": self.distance_error,
            "pans": self.pans,
            "distances": self.distances,
            **self.readouts,
            "start_pans": self.start_pans,
            "start_jitter": self.start_jitter,
            "learnt_distance": self.learnt_distance,
            **(self.walks.to_json() if self.walks is not None else {}),
            **(dict(self.motion) if self.motion is not None else {}),
            **(self.route.to_json() if self.route is not None else {}),
            **{f"lm_{k}": v for k, v in self.distance_stats.items()},
        }

    def scalars(self, steps_per_second: float) -> Iterator[tuple[str, float]]:
        """TensorBoard's (tag, value) pairs; ``steps_per_second`` is the wall-clock rate, kept
        out of the record."""
        yield "coder/reward", self.reward
        for k, v in self.errors.items():
            yield f"coder/error_{k}", v
        for k, v in self.policy_stats.items():
            yield f"policy/{k}", v
        for k, v in self.distance_stats.items():
            yield f"distance/lm_{k}", v
        yield "pursuit/mae", self.mae
        yield "pursuit/mae_recent", self.mae_recent
        for label, v in self.mae_per_position.items():
            yield f"pursuit/mae_{label}cm", v
        for rng, v in self.distance_error.items():
            yield f"distance/error_pct_{rng}", v
        yield "perf/steps_per_second", steps_per_second
        yield "curriculum/stage", self.stage
        if self.route is not None:
            yield from self.route.scalars()
        if self.walks is not None:
            yield from self.walks.scalars()
        for k, v in (self.motion or {}).items():
            yield f"motion/{k}", v
