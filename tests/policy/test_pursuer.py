"""The eye's learner in the loop (parallax.policy.Pursuer): the transitions it learns from, the
rule at a trial's reset, θ(I0, I0), the reward change it hands the state, and a frozen pursuer;
fed hand-made frames (tests/scripted.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from parallax.policy import Pursuer
from tests.scripted import STATE_DIM, frames, policy

TURNS = [slice(0, 2)]


def _trial_and_the_next(pursuer: Pursuer) -> None:
    """Two iterations of a trial, then the first of the next, acting after each."""
    for iteration in (0, 1, 0):
        pursuer.see(frames(iteration, [0.0, 0.1], [-1.0, -2.0]))
        pursuer.act(0)


@pytest.mark.parametrize(("learn_reset_step", "updates"), [(False, 1), (True, 2)])
def test_the_step_across_a_trials_reset_is_learnt_only_when_asked(learn_reset_step, updates):
    nac = policy(feature_norm="none", learn_reset_step=learn_reset_step)
    with Pursuer(nac, TURNS) as pursuer:
        _trial_and_the_next(pursuer)
    assert pursuer.updates == updates  # the policy's updates: one step per robot of each
    assert int(nac.updates) == 2 * updates


def test_the_reference_state_is_taken_at_each_trials_start_only():
    nac = policy(feature_norm="difference")
    taken = []
    reference = torch.full((2, STATE_DIM), 0.5)
    with Pursuer(nac, TURNS) as pursuer:
        for iteration in (0, 1, 2, 0, 1):
            seen = frames(iteration, [0.0, 0.1], [-1.0, -2.0])
            if iteration == 0:  # the executor offers θ(I0, I0) at a trial's first iteration
                seen = replace(seen, reference=lambda: taken.append(1) or reference)
            pursuer.see(seen)
            pursuer.act(0)
    assert len(taken) == 2
    assert torch.equal(pursuer.reference[0], reference)


def test_a_policy_without_a_reference_state_never_asks_for_it():
    def refuse():
        raise AssertionError("θ(I0, I0) asked for")

    with Pursuer(policy(feature_norm="none"), TURNS) as pursuer:
        seen = frames(0, [0.0, 0.1], [-1.0, -2.0])
        pursuer.see(replace(seen, reference=refuse))
    assert pursuer.reference == [None]


def test_the_state_gets_the_last_steps_reward_change(monkeypatch):
    nac = policy(feature_norm="none")
    changes = []
    state = nac.state
    monkeypatch.setattr(nac, "state", lambda *a: changes.append(a[4]) or state(*a))
    with Pursuer(nac, TURNS) as pursuer:
        pursuer.see(frames(0, [0.0, 0.1], [-1.0, -2.0]))
        increments = pursuer.act(0)
        pursuer.see(frames(1, [0.0, 0.1], [-0.5, -3.0]))
    assert changes[0] is None  # no step before the trial's first
    rewards, before, sent = changes[1]
    assert rewards.tolist() == [-0.5, -3.0] and before.tolist() == [-1.0, -2.0]
    np.testing.assert_array_equal(sent, increments)
    assert set(increments.tolist()) <= set(nac.action_values.tolist())


def test_a_frozen_pursuer_learns_nothing_and_leaves_the_policy_as_it_found_it():
    nac = policy(feature_norm="zscore")
    before = {k: v.clone() for k, v in nac.state_dict().items() if torch.is_tensor(v)}
    with Pursuer(nac, TURNS, learn=False, greedy=True) as pursuer:
        assert not nac.training  # acting does not move the running feature statistics
        _trial_and_the_next(pursuer)
    assert nac.training and pursuer.statistics() == {}
    after = nac.state_dict()
    assert all(torch.equal(v, after[k]) for k, v in before.items())


def test_its_statistics_are_the_mean_of_the_updates():
    nac = policy(feature_norm="none", learn_reset_step=True)
    reported = []
    update = nac.update
    nac.update = lambda *a: reported.append(update(*a)) or reported[-1]
    with Pursuer(nac, TURNS) as pursuer:
        _trial_and_the_next(pursuer)
    assert len(reported) == 2
    for name, value in pursuer.statistics().items():
        assert value == pytest.approx((reported[0][name] + reported[1][name]) / 2)
