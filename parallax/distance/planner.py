"""Where to move next, or whether to stop: beyond the paper, its first future work (§7).

The paper's robot walks the whole lateral list L every presentation. §7 asks for a robot that
"should decide when to stop moving laterally, having generated enough information to perceive
the distance". Each trial is independent of the one before (the pan is reset to 0 at each new
position, §3.2), so the robot may visit any subset V of L, in any order.

The planner is derived from the robot's own confidence, not learnt by trial and error. It keeps
the last ``queue_size`` complete vectors s from full sweeps, each with its target distance. For
any subset V it fits an estimator of the distance from the pans at V: a weighted least-squares
fit of the inverse distance on those pans (:mod:`parallax.distance.inverse_distance`). The
fit's leave-one-out errors on the queue, on rows estimated near the current estimate, are the
expected error of V.

After each position, with the estimate d̂ from the positions visited so far, the robot weighs
each position it has not visited: the expected error of V ∪ {k} near d̂, plus the price of the
extra trial and of the extra travel. It moves to the best position if that lowers the expected
error plus the price of what it has done, and stops otherwise. The price is
``price_per_trial`` percentage points of expected error per trial (30 eye movements) plus
``price_per_cm`` per centimetre of lateral travel: out to the farthest position visited and
back to l0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from parallax.distance.inverse_distance import InverseDistanceFit as Fit
from parallax.distance.inverse_distance import fit_inverse_distance
from parallax.distance.settings import DistanceConfig, MovementConfig

#: Edges (m) of the distance bins the expected error is conditioned on; the grid is 3–10 m.
BIN_EDGES_M = (4.0, 5.0, 6.5, 8.0)


class MovementPlanner:
    """Chooses the next lateral position (an index into L) or stops, from the queue of full
    sweeps."""

    def __init__(
        self,
        lateral_positions: Sequence[float],
        *,
        queue_size: int = DistanceConfig.queue_size,
        price_per_trial: float = MovementConfig.price_per_trial,
        price_per_cm: float = MovementConfig.price_per_cm,
        ridge: float = 1.0e-6,
    ) -> None:
        """L, the queue's length (distance.queue_size) and the prices (movement.*) are the run's
        settings, checked by parallax.config; ``ridge`` keeps the fits' Gram matrices invertible."""
        self.lateral_positions = [float(l) for l in lateral_positions]
        if not (math.isfinite(ridge) and ridge >= 0):
            raise ValueError(f"ridge must be a finite number ≥ 0, got {ridge!r}")
        self.queue_size = int(queue_size)
        self.price_per_trial = float(price_per_trial)
        self.price_per_cm = float(price_per_cm)
        self.ridge = float(ridge)
        self.inputs = np.zeros((0, len(self.lateral_positions)))
        self.distances = np.zeros(0)
        self._fits: dict[tuple[int, ...], Fit] = {}

    # --- the queue of full sweeps --------------------------------------------------------------
    def observe(self, s: Sequence[float], distance_m: float) -> None:
        """A full sweep's vector s (a pan per position of L) and its target distance."""
        row = np.asarray(s, dtype=np.float64).reshape(1, -1)
        if row.shape[1] != len(self.lateral_positions) or not np.isfinite(row).all():
            raise ValueError(f"s must hold {len(self.lateral_positions)} finite pans, got {s!r}")
        if not (math.isfinite(distance_m) and distance_m > 0):
            raise ValueError(f"distance must be positive metres, got {distance_m!r}")
        self.inputs = np.concatenate([row, self.inputs])[: self.queue_size]
        self.distances = np.concatenate([[float(distance_m)], self.distances])[: self.queue_size]
        self._fits.clear()

    @property
    def is_ready(self) -> bool:
        """The queue is full."""
        return self.distances.size == self.queue_size

    # --- estimators --------------------------------------------------------------------------
    def fit(self, visited: Sequence[int]) -> Fit:
        """The estimator from the pans at positions ``visited`` (indices into L), cached until
        the queue changes."""
        key = tuple(sorted(int(k) for k in visited))
        if key not in self._fits:
            self._fits[key] = self._fit(key)
        return self._fits[key]

    def _fit(self, key: tuple[int, ...]) -> Fit:
        return fit_inverse_distance(self.inputs[:, list(key)], self.distances, self.ridge)

    def estimate(self, visited: Sequence[int], pans: Sequence[float]) -> float:
        """Distance (m) from the pans at ``visited``, in the same order."""
        order = np.argsort(np.asarray(visited))
        x = np.append(np.asarray(pans, dtype=np.float64)[order], 1.0)
        return float(1.0 / max(float(x @ self.fit(visited).weights), 1e-9))

    def expected_error(
        self, candidate: Sequence[int], given: Sequence[int] = (), near_m: float | None = None
    ) -> float:
        """Mean leave-one-out error (%) of the estimator of ``candidate`` on the queue's rows
        that the estimator of ``given`` (the positions visited so far) places in the distance
        bin of ``near_m``, the robot's present estimate; all rows if it has none yet."""
        errors = self.fit(candidate).loo_errors_pct
        if not given or near_m is None:
            return float(errors.mean())
        bins = np.digitize(self.fit(given).loo_estimates, BIN_EDGES_M)
        same = bins == np.digitize([near_m], BIN_EDGES_M)[0]
        return float(errors[same].mean()) if same.any() else float(errors.mean())

    # --- the decision ------------------------------------------------------------------------
    def price(self, visited: Sequence[int]) -> float:
        """The price (percentage points) of having visited ``visited``."""
        if not visited:
            return 0.0
        travel_cm = 2.0 * 100.0 * max(self.lateral_positions[k] for k in visited)
        return self.price_per_trial * len(visited) + self.price_per_cm * travel_cm

    def cost(self, candidate: Sequence[int], given: Sequence[int], near_m: float | None) -> float:
        """What visiting ``candidate`` is expected to cost: its :meth:`expected_error` plus its
        :meth:`price`, both in percentage points."""
        return self.expected_error(candidate, given, near_m) + self.price(candidate)

    def next_position(self, visited: Sequence[int], pans: Sequence[float]) -> int | None:
        """The index into L to visit next, or None to stop and estimate now."""
        visited = [int(k) for k in visited]
        candidates = [k for k in range(len(self.lateral_positions)) if k not in visited]
        if not candidates:
            return None
        near = self.estimate(visited, pans) if visited else None
        now = self.cost(visited, visited, near) if visited else math.inf
        costs = [self.cost([*visited, k], visited, near) for k in candidates]
        best = int(np.argmin(costs))
        return candidates[best] if costs[best] < now else None

    def state_dict(self) -> dict:
        return {"inputs": self.inputs.copy(), "distances": self.distances.copy()}

    def load_state_dict(self, state: dict) -> None:
        inputs, distances = np.asarray(state["inputs"]), np.asarray(state["distances"])
        if inputs.ndim != 2 or inputs.shape[1] != len(self.lateral_positions):
            raise ValueError(f"planner state is for {inputs.shape[1:]} positions, not this L")
        self.inputs, self.distances = inputs.copy(), distances.copy()
        self._fits.clear()

    def plan(self, s: Sequence[float]) -> tuple[list[int], float]:
        """The positions the robot would visit for a presentation whose full vector is ``s``
        (it sees only the pans it visits), and its estimate when it stops."""
        s = np.asarray(s, dtype=np.float64)
        visited: list[int] = []
        while (k := self.next_position(visited, s[visited])) is not None:
            visited.append(k)
        return visited, self.estimate(visited, s[visited])
