"""What a route is to the paper's loop (§3.2) and to the trainer: the interfaces of
:mod:`parallax.routes`.

The loop (:func:`parallax.loop.presentation`) asks its :class:`Route` where to go before the first
trial and at the end of each; a route that the robot chooses moves the worlds there through the
loop's executor (:class:`Worlds`). The trainer asks the run's :class:`Movement`, before each
presentation, for the route it follows, and after it for what the route learnt and cost.
"""

from __future__ import annotations

from typing import Protocol

from parallax.presentation import Presentation
from parallax.record import Route as RouteRecord


class Worlds(Protocol):
    """The loop's executor, as a route sees it (:class:`parallax.executor.Executor`)."""

    @property
    def trials(self) -> int: ...  # the trials of a sweep of the worlds' list L

    def start_route(self, lateral_m: float) -> None: ...  # before the reset
    def visit_next(self, lateral_m: float) -> None: ...  # at a trial's last iteration


class Route(Protocol):
    """Where the robot goes within one presentation."""

    #: whether the robot chooses its positions: the record lists them, the others' pans are NaN
    chosen: bool

    def where_next(self, run: Worlds, visited: list[int], so_far: Presentation) -> int | None:
        """The next position (an index into L) after those ``visited`` (none yet: the first),
        or None to stop; ``so_far`` is the presentation's record as it stands."""
        ...


class Movement(Protocol):
    """How the robot moves over a run: each presentation's route, and what it learns from it."""

    def route(self) -> Route: ...
    def after(self, pres: Presentation, learnt_distance: bool) -> RouteRecord | None: ...
    def summary(self) -> dict: ...
    def state_dict(self) -> dict: ...
    def load_state_dict(self, state: dict) -> None: ...
