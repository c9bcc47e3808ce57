"""The distance learner's step after each sweep (paper §3.5), online, with its targets.

After a presentation that swept L, each robot's s = [q1 … qr] is predicted first (the honest
online error), then queued with its target (eq. 9) and the network fitted. The target comes
from the supervisor (:class:`Supervised`, the paper: each panel's distance) or, beyond the
paper (§7), from the robot's own walk to the panel (:class:`Odometry`: the strides it counted).
:func:`distance_step` picks the one of the run's distance.targets.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from parallax.distance import DistanceLearner
from parallax.envs.walk import Walker, walk_robots
from parallax.metrics import DistanceErrorTracker
from parallax.parts import Parts, truths_at
from parallax.record import Walks


def learn_online(
    learner,
    tracker: DistanceErrorTracker,
    pans: np.ndarray,
    truths: np.ndarray,
    readings: Sequence[float | None] | None = None,
    *,
    distances: np.ndarray | None = None,
) -> dict[str, float]:
    """Paper §3.5 online: predict each new s before learning it (the honest online error against
    ``truths``, kept by `tracker`), then queue it with its target (eq. 9) and fit. The rows of
    ``pans`` are one presentation's vectors, one per robot: all are predicted, then queued, then
    fitted once (with one robot, exactly the paper's loop; see
    ``DistanceLearner.observe_batch``). ``readings`` are what the target source makes targets
    from (default: ``truths``, the supervisor's distances); a None reading (a robot that did not
    walk) is predicted but not learnt; ``distances``, the panels' (when the truths are in another
    unit), place the errors in the ranges. Returns the fit's statistics ({} if none). Shared by the
    trainer and parallax-replay so that a replay is the run's distance learner."""
    pans = np.atleast_2d(np.asarray(pans, dtype=np.float64))
    truths = np.asarray(truths, dtype=np.float64).reshape(-1)
    readings = list(truths) if readings is None else list(readings)
    at = [None] * len(truths) if distances is None else np.asarray(distances).reshape(-1)
    if learner.is_ready:
        predictions = np.asarray(learner.predict(pans), dtype=np.float64).reshape(-1)
        for predicted, truth, panel in zip(predictions, truths, at):
            tracker.record(float(predicted), float(truth), None if panel is None else float(panel))
    labelled = [i for i, reading in enumerate(readings) if reading is not None]
    if not labelled:
        return {}
    stats = learner.observe_batch(pans[labelled], [float(readings[i]) for i in labelled])
    return {k: float(v) for k, v in stats.items()} if stats else {}


class Supervised:
    """The paper's targets: the supervisor gives each panel's distance."""

    walks = False

    def __init__(self, learner: DistanceLearner) -> None:
        self.learner = learner

    def __call__(
        self, pans: np.ndarray, distances: np.ndarray, tracker: DistanceErrorTracker
    ) -> tuple[dict[str, float], Walks | None]:
        """Learn one presentation's vectors; the fit's statistics and no walks."""
        return learn_online(self.learner, tracker, pans, distances), None

    def truths(self, distances: np.ndarray) -> np.ndarray:
        """What a perfect distance learner answers for panels at ``distances``."""
        return np.asarray(distances, dtype=np.float64)


class Odometry(Supervised):
    """Targets from the body (beyond the paper, §7): after a sweep each robot walks to its
    panel with probability distance.odometry.walk_fraction and counts its strides."""

    walks = True

    def __init__(self, learner: DistanceLearner, worlds: list, walkers: list[Walker]) -> None:
        super().__init__(learner)
        self.worlds, self.walkers = worlds, walkers

    def __call__(
        self, pans: np.ndarray, distances: np.ndarray, tracker: DistanceErrorTracker
    ) -> tuple[dict[str, float], Walks]:
        """The walks, then the counted strides learnt; the fit's statistics and the walks."""
        source = self.learner.target_source
        physics = [world.physics for world in self.worlds]
        counted, reach = walk_robots(physics, self.walkers, source.walk_fraction)
        truths = [source.truth(d, r) for d, r in zip(distances, reach)]
        stride, nominal = self.walkers[0].true_stride_m, source.nominal_stride_m
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
        stats = learn_online(self.learner, tracker, pans, truths, counted, distances=distances)
        return stats, walked

    def truths(self, distances: np.ndarray) -> np.ndarray:
        """The odometry's slip-free reading for panels at ``distances``, robot 0's body as it
        is now."""
        source = self.learner.target_source
        return truths_at(source, self.walkers[0], self.worlds[0].physics, distances)


def distance_step(parts: Parts) -> Supervised:
    """The step of the run's distance.targets."""
    if parts.distance.target_source.walks:
        return Odometry(parts.distance, parts.worlds, parts.walkers)
    return Supervised(parts.distance)
