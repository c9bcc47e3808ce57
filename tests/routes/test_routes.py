"""The routes (parallax.routes): the paper's sweep goes through L in order (a continuous motion's
one trial sweeps it) and moves nothing; a chosen route moves the worlds to each position it
chooses (the loop with both is tests/test_loop.py's; the planner's, tests/test_movement.py's)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from parallax.routes import SWEEP, Chosen, Sweep


class _Worlds:
    def __init__(self, trials: int) -> None:
        self.trials, self.moves = trials, []

    def start_route(self, lateral_m: float) -> None:
        self.moves.append(("start", lateral_m))

    def visit_next(self, lateral_m: float) -> None:
        self.moves.append(("next", lateral_m))


SO_FAR = SimpleNamespace(lateral_positions=[0.05, 0.1, 0.15], pans=np.full((1, 3), np.nan))


def _walk(route, worlds) -> list[int]:
    visited: list[int] = []
    while (p := route.where_next(worlds, visited, SO_FAR)) is not None:
        visited.append(p)
    return visited


def test_the_sweep_visits_every_position_in_order_and_moves_nothing():
    for trials in (3, 1):  # one: the continuous motion's trial
        worlds = _Worlds(trials)
        assert _walk(SWEEP, worlds) == list(range(trials)) and worlds.moves == []
    sweeping = Sweep()  # the run's movement that sweeps every presentation
    assert not SWEEP.chosen and sweeping.route() is sweeping and sweeping.after(None, True) is None


def test_a_chosen_route_starts_the_worlds_and_moves_them_on():
    order = [2, 0]
    route = Chosen(lambda visited, _: order[len(visited)] if len(visited) < len(order) else None)
    worlds = _Worlds(3)
    assert route.chosen and _walk(route, worlds) == order
    assert worlds.moves == [("start", 0.15), ("next", 0.05)]
