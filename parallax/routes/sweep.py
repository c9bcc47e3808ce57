"""The paper's route (§3.2, Fig. 3): every position of L, in order, the same every presentation.

With the body sweeping L in one trial (``env.motion=continuous``, beyond the paper) the route is
that one trial. The worlds go through L by themselves (an episode of r trials), so the route
moves nothing.
"""

from __future__ import annotations

from parallax.presentation import Presentation
from parallax.record import Route as RouteRecord
from parallax.routes.route import Route, Worlds


class Sweep:
    """Every position of L in order: a presentation's :class:`~parallax.routes.route.Route`,
    and the run's :class:`~parallax.routes.route.Movement` that sweeps every presentation."""

    chosen = False

    def where_next(self, run: Worlds, visited: list[int], so_far: Presentation) -> int | None:
        return len(visited) if len(visited) < run.trials else None

    # --- the run's movement: nothing to learn or to keep -----------------------------------------
    def route(self) -> Route:
        return self

    def after(self, pres: Presentation, learnt_distance: bool) -> RouteRecord | None:
        return None

    def summary(self) -> dict:
        return {}

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:
        pass


#: The paper's route, for a presentation that sweeps L.
SWEEP = Sweep()
