"""Where the robot goes in a presentation: a route, one strategy per file (paper §3.2; §7).

* :mod:`~parallax.routes.sweep`: the paper's, every position of L in order (a continuous
  motion's one trial sweeps L);
* :mod:`~parallax.routes.chosen`: a route the robot chooses as it goes, the world moved to each
  position it chooses;
* :mod:`~parallax.routes.planned`: the planner of §7 choosing that route once it has learnt
  enough, and sweeps in between.

:mod:`~parallax.routes.route` holds the interfaces: the loop's :class:`Route` and the trainer's
:class:`Movement`; :func:`movement` is the run's, from its config.
"""

from __future__ import annotations

from omegaconf import DictConfig

from parallax.parts import Parts
from parallax.readouts import PanReadout
from parallax.routes.chosen import Chosen
from parallax.routes.planned import Planned, planned_route
from parallax.routes.route import Movement, Route, Worlds
from parallax.routes.sweep import SWEEP, Sweep

__all__ = [
    "SWEEP",
    "Chosen",
    "Movement",
    "Planned",
    "Route",
    "Sweep",
    "Worlds",
    "movement",
    "planned_route",
]


def movement(cfg: DictConfig, parts: Parts, readout: type[PanReadout]) -> Movement:
    """The run's movement: a sweep of L, or planned routes (movement.route=planned) reading s
    as ``readout``."""
    if parts.planner is None:
        return Sweep()
    window = int(cfg.metrics.distance_window)
    return Planned(parts.planner, parts.explore, float(cfg.movement.explore), readout, window)
