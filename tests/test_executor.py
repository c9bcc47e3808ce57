"""What the executors share (parallax.executor.Executor), with scripted worlds and coder
(tests/scripted.py): typed observations, θ(I0, I0) offered at a trial's first iteration only and
before the iteration's dictionary step, and no dictionary step in a frozen presentation. That the
lockstep gives the plain sequence's numbers is tests/test_experiment.py's."""

from __future__ import annotations

import pytest

from parallax.envs.observation import Observation
from tests.scripted import scripted

TRIAL = 3


def _iteration(run, increments=(0.05, 0.05)):
    """One iteration of two turns of one robot each: their frames, then their steps."""
    seen = []
    for turn in range(len(run.turns)):
        seen.append(run.frames(turn))
        run.step(turn, increments[:1])
    return seen


def test_frames_carry_typed_observations_and_theta_i0_i0_at_a_trials_start_only():
    parts, run = scripted(2, (0.05, 0.1), TRIAL, per_turn=1)
    with run:
        run.reset(learn=True)
        first = _iteration(run)
        second = _iteration(run)
    assert all(isinstance(o, Observation) for f in first + second for o in f.observations)
    assert [f.robots for f in first] == [slice(0, 1), slice(1, 2)]
    assert all(f.starts_trial and f.reference is not None for f in first)
    assert all(not f.starts_trial and f.reference is None for f in second)
    assert second[0].pans.tolist() == [0.05] and second[0].rewards.dtype.name == "float64"


def test_the_dictionary_step_of_a_trials_start_waits_for_theta_i0_i0_or_the_step():
    parts, run = scripted(2, (0.05, 0.1), TRIAL, per_turn=1)
    calls = parts.coder.calls
    with run:
        run.reset(learn=True)
        run.frames(0)
        run.step(0, [0.0])
        last = run.frames(1)
        assert "dictionary step" not in calls  # θ(I0, I0) may still be asked for
        last.reference()
        assert calls[-2:] == ["θ(I0, I0)", "dictionary step"]
        run.step(1, [0.0])
        run.frames(0)
        run.step(0, [0.0])
        run.frames(1)  # not a trial's start: the step starts with the last turn's frames
        assert calls[-2:] == ["I(t)", "dictionary step"]
    with pytest.raises(RuntimeError, match="until it steps"):
        last.reference()  # the dictionaries have moved on since


@pytest.mark.parametrize(("learn", "coder_learns"), [(False, True), (True, False)])
def test_no_dictionary_step_unless_the_presentation_and_the_coder_learn(learn, coder_learns):
    parts, run = scripted(1, (0.05,), TRIAL, learn=coder_learns)
    with run:
        run.reset(learn=learn)
        for _ in range(TRIAL - 1):
            run.frames(0)
            run.step(0, [0.0])
        run.frames(0)
    assert "dictionary step" not in parts.coder.calls


def test_the_last_iterations_dictionary_step_is_taken_on_leaving():
    parts, run = scripted(1, (0.05,), 1)  # every iteration is a trial's first
    with run:
        run.reset(learn=True)
        run.frames(0)
        assert "dictionary step" not in parts.coder.calls
    assert parts.coder.calls[-1] == "dictionary step"
