"""A route the robot chooses as it goes (beyond the paper, its first future work, §7).

Each trial is independent of the one before (the pan is reset at each new position, §3.2), so
the robot may visit any positions of L, in any order, each at most once. A :class:`Chosen` route
asks its chooser where next and moves the world there through the loop's executor.
"""

from __future__ import annotations

from collections.abc import Callable

from parallax.presentation import Presentation
from parallax.routes.route import Worlds

#: (positions visited so far, the presentation as it stands) → an index into L, or None to stop.
Chooser = Callable[[list[int], Presentation], int | None]


class Chosen:
    """One robot's route from ``choose``: the world starts at its first position and goes to
    each next one at the end of a trial."""

    chosen = True

    def __init__(self, choose: Chooser) -> None:
        self.choose = choose

    def where_next(self, run: Worlds, visited: list[int], so_far: Presentation) -> int | None:
        if not visited:
            return self._first(run, so_far)
        after = self.choose(list(visited), so_far)
        if after in visited:
            raise ValueError(f"the route visits position {after} of L twice")
        if after is not None:
            run.visit_next(so_far.lateral_positions[after])
        return after

    def _first(self, run: Worlds, so_far: Presentation) -> int:
        robots = so_far.pans.shape[0]
        if robots != 1:
            raise ValueError(f"a chosen route needs env.robots=1, got {robots}")
        first = self.choose([], so_far)
        if first is None:
            raise ValueError("a route must visit at least one lateral position")
        run.start_route(so_far.lateral_positions[first])
        return first
