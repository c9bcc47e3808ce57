"""The paper's loop (parallax.loop.presentation) over scripted worlds and coder
(tests/scripted.py): the positions and iterations it goes through, q_p, the route's moves through
the executor, the order of θ(I0, I0) and the dictionary step, and a frozen presentation. The loop
with the real worlds and coder, scheduled on threads or not, is tests/test_experiment.py's."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from parallax import loop
from parallax.routes import Chosen
from tests.scripted import scripted

LATERAL = (0.05, 0.1, 0.15)
TRIAL = 4


def _route(order):
    """A chosen route through ``order`` (indices into L), then a stop."""
    return Chosen(lambda visited, _: order[len(visited)] if len(visited) < len(order) else None)


@pytest.mark.parametrize(("robots", "per_turn"), [(1, 0), (3, 2)])
def test_a_presentation_visits_each_position_for_a_trial_and_steps_in_between(robots, per_turn):
    parts, run = scripted(robots, LATERAL, TRIAL, per_turn)
    pres = loop.presentation(parts, run)
    every = [(p, t) for p in range(len(LATERAL)) for t in range(TRIAL)]
    for world in parts.worlds:
        assert [(p, t) for p, t, _ in world.seen] == every  # no step after the last iteration
        assert world.moves == [("reset",)]
    assert pres.steps == len(every) and pres.route is None
    assert pres.lateral_positions == list(LATERAL)
    assert pres.distances.tolist() == [5.0] * robots and pres.textures.tolist() == [0] * robots


def test_q_p_is_the_pan_at_each_trials_last_iteration():
    parts, run = scripted(2, LATERAL, TRIAL)
    pres = loop.presentation(parts, run)
    for b, world in enumerate(parts.worlds):
        pans = {(p, t): pan for p, t, pan in world.seen}
        assert pres.pans[b].tolist() == [pans[p, TRIAL - 1] for p in range(len(LATERAL))]
        assert pres.start_pans[b].tolist() == [pans[p, 0] for p in range(len(LATERAL))]
        assert pres.targets[b].tolist() == pytest.approx([10.0 * l for l in LATERAL])
    assert len(set(pres.pans.ravel().tolist())) > 1  # the eyes moved


def test_a_chosen_route_moves_the_world_through_the_executor():
    parts, run = scripted(1, LATERAL, TRIAL)
    pres = loop.presentation(parts, run, route=_route([2, 0]))
    world = parts.worlds[0]
    # the route starts before the reset and the next position comes at the trial's last
    # iteration (ScriptedWorld.visit_next checks it)
    assert world.moves == [("start_route", LATERAL[2]), ("reset",), ("visit_next", LATERAL[0])]
    assert pres.route == [2, 0] and pres.steps == 2 * TRIAL
    assert np.isnan(pres.pans[0, 1]) and np.isfinite(pres.pans[0, [0, 2]]).all()
    assert pres.targets[0, [2, 0]].tolist() == pytest.approx([1.5, 0.5])


@pytest.mark.parametrize(
    ("route", "robots", "message"),
    [
        (_route([1, 1]), 1, "twice"),
        (_route([]), 1, "at least one"),
        (_route([0]), 2, "env.robots=1"),
    ],
)
def test_a_route_that_revisits_stops_at_once_or_takes_robots_is_refused(route, robots, message):
    parts, run = scripted(robots, LATERAL, TRIAL)
    with pytest.raises(ValueError, match=message):
        loop.presentation(parts, run, route=route)


@pytest.mark.parametrize("feature_norm", ["difference", "none"])
def test_the_dictionary_step_of_a_trials_start_waits_for_the_reference_state(feature_norm):
    parts, run = scripted(1, LATERAL[:2], 3, feature_norm=feature_norm)
    loop.presentation(parts, run)
    calls = parts.coder.calls
    assert calls[0] == "I0" and calls.count("dictionary step") == 2 * 3  # one per iteration
    iterations = []  # what each iteration asked of the coder after encoding I(t)
    for call in calls[1:]:
        if call == "I(t)":
            iterations.append([])
        else:
            iterations[-1].append(call)
    if feature_norm == "difference":  # θ(I0, I0) at each trial's start, before the step
        trial = [["θ(I0, I0)", "dictionary step"]] + [["dictionary step"]] * 2
        assert iterations == trial * 2
    else:
        assert iterations == [["dictionary step"]] * 6


@pytest.mark.parametrize("coder_learns", [True, False])
def test_a_frozen_presentation_changes_neither_policy_nor_dictionaries(coder_learns):
    parts, run = scripted(2, LATERAL, TRIAL, learn=coder_learns)
    before = {k: v.clone() for k, v in parts.policy.state_dict().items() if torch.is_tensor(v)}
    pres = loop.presentation(parts, run, learn=False, greedy=True)
    after = parts.policy.state_dict()
    assert all(torch.equal(v, after[k]) for k, v in before.items())
    assert parts.policy.training and pres.policy_stats == {}
    assert "dictionary step" not in parts.coder.calls
    if coder_learns:  # learning, both learn
        parts, run = scripted(2, LATERAL, TRIAL)
        assert loop.presentation(parts, run).policy_stats["valid_fraction"] == 1.0
        assert int(parts.policy.updates) > 0 and "dictionary step" in parts.coder.calls
