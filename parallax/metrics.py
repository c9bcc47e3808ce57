"""Training metrics of the paper: eye-movement MAE (eq. 16), its Table 2–3 summary, and the
online distance-estimation error per range (Tables 4–5).

A *trial* is the t_h iterations at one lateral position; its error is |α − α*| at the last
iteration (eq. 16 samples α(t + 29 + 30k)). The MAE is the mean over a sliding window of the
last ``window`` trials — over all positions together and per position.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np


def position_label(lateral_m: float) -> str:
    """'5', '13', '7.5' … : a lateral position in the paper's unit (cm)."""
    return f"{lateral_m * 100:.4g}"


class EyeMovementTracker:
    """Per-trial pursuit errors at the end of each trial, overall and per lateral position."""

    def __init__(self, lateral_positions: Sequence[float], window: int = 1000):
        self.labels = [position_label(l) for l in lateral_positions]
        self.window = int(window)
        self.overall: deque[float] = deque(maxlen=self.window)
        self.per_position = {k: deque(maxlen=self.window) for k in self.labels}
        self.trials = 0

    def record(self, label: str, pan_deg: float, target_deg: float) -> None:
        err = abs(float(pan_deg) - float(target_deg))
        self.overall.append(err)
        self.per_position[label].append(err)
        self.trials += 1

    def mae(self) -> float:
        return float(np.mean(self.overall)) if self.overall else float("nan")

    def recent_mae(self, n: int = 100) -> float:
        """Mean error of the last ``n`` trials (all positions): early learning shows here long
        before it moves the eq. (16) window."""
        tail = list(self.overall)[-n:]
        return float(np.mean(tail)) if tail else float("nan")

    def mae_per_position(self) -> dict[str, float]:
        return {k: float(np.mean(v)) if v else float("nan") for k, v in self.per_position.items()}

    def last_trials(self, n: int = 100) -> dict[str, dict[str, float]]:
        """Table 2–3 cells: average and variance of the last ``n`` trials at each position."""
        out = {}
        for k, v in self.per_position.items():
            tail = np.asarray(list(v)[-n:], dtype=np.float64)
            out[k] = {
                "mean": float(tail.mean()) if tail.size else float("nan"),
                "var": float(tail.var()) if tail.size else float("nan"),
                "trials": int(tail.size),
            }
        return out

    def state_dict(self) -> dict:
        return {
            "overall": list(self.overall),
            "trials": self.trials,
            "per_position": {k: list(v) for k, v in self.per_position.items()},
        }

    def load_state_dict(self, state: dict) -> None:
        self.overall = deque(state["overall"], maxlen=self.window)
        self.per_position = {
            k: deque(state["per_position"].get(k, []), maxlen=self.window) for k in self.labels
        }
        self.trials = int(state["trials"])


class DistanceErrorTracker:
    """Distance predictions made for each new s *before* it is learnt (an honest online test)."""

    def __init__(self, window: int = 500):
        self.window = int(window)
        self.pairs: deque[tuple[float, float]] = deque(maxlen=self.window)

    def record(self, predicted_m: float, true_m: float, at_m: float | None = None) -> None:
        """A prediction and its truth; ``at_m``: the panel's distance when the truth is in
        another unit (odometry's), for the ranges."""
        pair = (float(predicted_m), float(true_m))
        self.pairs.append(pair if at_m is None else (*pair, float(at_m)))

    def by_range(self) -> dict[str, float]:
        """Errors by range of the panels' distances, as parallax-eval's."""
        from parallax.distance.metrics import distance_error_by_range

        if not self.pairs:
            return {}
        pred = np.array([p[0] for p in self.pairs], dtype=np.float64)
        true = np.array([p[1] for p in self.pairs], dtype=np.float64)
        at = np.array([p[-1] for p in self.pairs], dtype=np.float64)  # the truth if no panel
        return distance_error_by_range(pred, true, at=at)

    def state_dict(self) -> dict:
        return {"pairs": list(self.pairs)}

    def load_state_dict(self, state: dict) -> None:
        self.pairs = deque((tuple(p) for p in state["pairs"]), maxlen=self.window)


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
