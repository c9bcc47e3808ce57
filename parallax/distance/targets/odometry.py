"""Beyond the paper (§7's second future work): targets from the robot's own body.

After the sweep the robot walks to the panel until its hand touches it (parallax.envs.walk) and
its target is the strides it counted times the stride it believes it has: its body's unit, not
the supervisor's. A growth spurt (env.walk) changes the body's true stride, not this one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from torch import Tensor

from parallax.distance.online import learn_online
from parallax.distance.targets.base import TargetSource
from parallax.envs.walk import walk_robots
from parallax.record import Walks


@dataclass
class OdometryConfig:
    """The robot's own measure of distance for distance.targets=odometry: strides counted on
    a walk to the panel (env.walk) times the stride length it believes it has."""

    #: Fraction of presentations that end with a walk (walking is costly); the others give the
    #: learner no target and are only predicted.
    walk_fraction: float = 1.0
    #: The stride length the robot believes it has (m): its unit of distance.
    nominal_stride_m: float = 0.05


class OdometryTargets(TargetSource):
    """Strides walked to touch the panel × the stride the robot believes it has (metres of its
    own): the embodied meaning of "how far" (§7). A growth spurt changes the true stride, not
    this one, so the targets follow the body."""

    name = "odometry"
    walks = True

    def __init__(
        self,
        walk_fraction: float = OdometryConfig.walk_fraction,
        nominal_stride_m: float = OdometryConfig.nominal_stride_m,
    ) -> None:
        self.walk_fraction = float(walk_fraction)
        self.nominal_stride_m = float(nominal_stride_m)

    def __call__(self, s: Tensor, reading: float) -> float:
        strides = float(reading)
        if not math.isfinite(strides) or strides <= 0:
            raise ValueError(f"a walk's stride count must be positive and finite, got {strides!r}")
        return strides * self.nominal_stride_m

    def truth(self, distance_m: float, walk_length_strides: float) -> float:
        del distance_m
        return float(walk_length_strides) * self.nominal_stride_m

    def learn(
        self, learner, tracker, pans: np.ndarray, distances: np.ndarray, bodies: Any
    ) -> tuple[dict[str, float], Walks]:  # type: ignore[no-untyped-def]
        """Each robot walks to its panel with probability walk_fraction and counts its strides;
        the counts are learnt (a robot that stayed is predicted, not learnt). The fit's
        statistics and the walks."""
        physics = [world.physics for world in bodies.worlds]
        counted, reach = walk_robots(physics, bodies.walkers, self.walk_fraction)
        truths = [self.truth(d, r) for d, r in zip(distances, reach)]
        stride, nominal = bodies.walkers[0].true_stride_m, self.nominal_stride_m
        walked = Walks(
            walk_strides=counted,
            reach_strides=reach,
            # what the robot believes it walked against what it walked, in %
            odometry_error_pct=[
                None if n is None else 100.0 * (n * nominal / (r * stride) - 1.0)
                for n, r in zip(counted, reach)
            ],
            true_stride_m=stride,
        )
        stats = learn_online(learner, tracker, pans, truths, counted, distances=distances)
        return stats, walked

    def truths(self, distances: np.ndarray, bodies: Any) -> np.ndarray:
        """The slip-free walk's reading for panels at ``distances``, robot 0's body as it is
        now."""
        walker, physics = bodies.walkers[0], bodies.worlds[0].physics
        return np.array(
            [self.truth(d, walker.reach_strides(physics, d)) for d in distances], dtype=np.float64
        )
