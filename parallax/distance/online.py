"""The distance learner's online step after each sweep (paper §3.5): predict, then learn.

Each robot's new s is predicted first, against the truth a perfect learner would answer (the
honest online error of Tables 4–5), then queued with its target (eq. 9) and the network fitted.
The target sources (:mod:`parallax.distance.targets`) and parallax-replay take this step, so a
replay is the run's distance learner.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def learn_online(  # type: ignore[no-untyped-def]
    learner,
    tracker,  # records (predicted, truth, panel's distance): parallax.metrics.DistanceErrorTracker
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
