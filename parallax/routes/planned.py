"""A robot that plans its route (beyond the paper, its first future work, §7).

:class:`Planned` is the run's movement with ``movement.route=planned``: once it has learnt enough
(the planner's queue is full), a presentation stops sweeping L and asks
:class:`parallax.distance.planner.MovementPlanner` where to look next and when to stop
(:func:`planned_route`); with probability ``movement.explore`` it sweeps L still, so that the
planner's queue keeps learning from full sweeps.
"""

from __future__ import annotations

import numpy as np

from parallax.distance.planner import MovementPlanner
from parallax.metrics import DistanceErrorTracker
from parallax.presentation import Presentation
from parallax.readouts import PanReadout
from parallax.record import Route as RouteRecord
from parallax.routes.chosen import Chosen
from parallax.routes.route import Route
from parallax.routes.sweep import SWEEP


def planned_route(planner: MovementPlanner, readout: type[PanReadout]) -> Chosen:
    """The planner's route, reading s as ``readout`` (train.distance_readout's)."""

    def choose(visited: list[int], so_far: Presentation) -> int | None:
        pans = so_far.read(readout)[0]
        return planner.next_position(visited, pans[visited])

    return Chosen(choose)


class Planned:
    """A planned route once the planner's queue is full, else (and with probability ``explore``)
    a sweep, whose vectors the planner's queue learns; its routes' estimates are scored online
    apart from the sweeps' network."""

    def __init__(
        self,
        planner: MovementPlanner,
        explore_random: np.random.RandomState,
        explore: float,
        readout: type[PanReadout],
        window: int,
    ) -> None:
        self.planner, self.explore_random, self.explore = planner, explore_random, float(explore)
        self.readout = readout
        self.errors = DistanceErrorTracker(window=window)

    def route(self) -> Route:
        draw = self.explore_random.random_sample()  # drawn every time, ready or not
        if not self.planner.is_ready or draw < self.explore:
            return SWEEP
        return planned_route(self.planner, self.readout)

    def after(self, pres: Presentation, learnt_distance: bool) -> RouteRecord:
        pans = pres.read(self.readout)[0]
        if learnt_distance and pres.route is None:  # a full sweep: the planner's queue learns it
            self.planner.observe(pans, float(pres.distances[0]))
        lateral_cm = [100.0 * l for l in pres.lateral_positions]
        visited = list(range(len(lateral_cm))) if pres.route is None else pres.route
        estimate = None
        if pres.route is not None and learnt_distance:
            estimate = self.planner.estimate(pres.route, pans[pres.route])
            self.errors.record(estimate, float(pres.distances[0]))
        return RouteRecord(
            route=pres.route,
            trials=len(visited),
            travel_cm=2.0 * max(lateral_cm[k] for k in visited),
            route_distance_error=self.errors.by_range(),
            estimate=estimate,
        )

    def summary(self) -> dict:
        return {"route_distance_error": self.errors.by_range()}

    def state_dict(self) -> dict:
        return {"route_dist": self.errors.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.errors.load_state_dict(state["route_dist"])
