"""Training metrics of the paper: eye-movement MAE (eq. 16), its Table 2–3 summary, and the
online distance-estimation error per range (Tables 4–5).

A *trial* is the t_h iterations at one lateral position; its error is |α − α*| at the last
iteration (eq. 16 samples α(t + 29 + 30k)). The MAE is the mean over a sliding window of the
last ``window`` trials — over all positions together and per position.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Any

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


def finite_or_none(value: Any) -> Any:
    """``value`` with every float that is not finite (a range no panel fell in, a position not
    yet visited) as None: strict JSON, which has no NaN, for summary.json."""
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
