"""The lockstep of parallax.experiment (issue 7): the worlds step on the GL thread while the coder
works, robots are encoded chunk by chunk, and none of it changes a number."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import torch

from parallax.config import compose
from parallax.experiment import Experiment


def _presentations(
    overrides: list[str], chunk: int, count: int = 2, early_dictionary_step: bool = True
):
    """``count`` presentations of a fresh experiment encoding ``chunk`` robots at a time (its
    dictionary steps on the helper thread from the policy's turn on, or on the caller's while the
    world renders), and the state of its coder and policy afterwards."""
    previous = Experiment.ENCODE_CHUNK, Experiment.EARLY_DICTIONARY_STEP
    Experiment.ENCODE_CHUNK, Experiment.EARLY_DICTIONARY_STEP = chunk, early_dictionary_step
    exp = Experiment(compose(overrides))
    try:
        presentations = [exp.run_presentation() for _ in range(count)]
        return presentations, exp.coder.state_dict(), exp.policy.state_dict()
    finally:
        Experiment.ENCODE_CHUNK, Experiment.EARLY_DICTIONARY_STEP = previous
        exp.close()


def _assert_same(first, second) -> None:
    (presentations_a, coder_a, policy_a), (presentations_b, coder_b, policy_b) = first, second
    for a, b in zip(presentations_a, presentations_b, strict=True):
        for field in ("pans", "best_pans", "targets", "start_pans", "distances", "textures"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
        assert a.reward == b.reward and a.errors == b.errors and a.policy_stats == b.policy_stats
    for name in coder_a:
        assert torch.equal(coder_a[name], coder_b[name]), name
    for name, value in policy_a.items():
        if isinstance(value, torch.Tensor):
            assert torch.equal(value, policy_b[name]), name


@pytest.mark.parametrize("extra", [[], ["policy.feature_norm=difference"]])
def test_robots_encoded_chunk_by_chunk_give_the_numbers_of_one_batch(tiny_overrides, extra) -> None:
    overrides = tiny_overrides + ["env.robots=3", "env.initial_pan_jitter_deg=1", *extra]
    one_batch = _presentations(overrides, chunk=3)
    _assert_same(_presentations(overrides, chunk=1), one_batch)
    _assert_same(_presentations(overrides, chunk=2), one_batch)  # chunks of 2 and 1


@pytest.mark.parametrize(("robots", "extra"), [(1, []), (3, ["policy.feature_norm=difference"])])
def test_the_dictionary_step_on_the_helper_thread_changes_no_number(
    tiny_overrides, robots, extra
) -> None:
    overrides = tiny_overrides + [f"env.robots={robots}", "env.initial_pan_jitter_deg=1", *extra]
    on_the_caller = _presentations(overrides, chunk=2, early_dictionary_step=False)
    _assert_same(_presentations(overrides, chunk=2, early_dictionary_step=True), on_the_caller)


def test_an_error_during_the_step_waits_for_the_dictionary_step(
    tiny_overrides, monkeypatch
) -> None:
    exp = Experiment(compose(tiny_overrides))
    try:
        steps = []
        slow_learn = exp.coder.learn_from

        def learn_slowly(encodings) -> None:
            threading.Event().wait(0.2)
            slow_learn(encodings)
            steps.append("learnt")

        def failing_act(*_args, **_kwargs):
            raise RuntimeError("policy failed")

        monkeypatch.setattr(exp.coder, "learn_from", learn_slowly)
        monkeypatch.setattr(exp.policy, "act", failing_act)
        with pytest.raises(RuntimeError, match="policy failed"):
            exp.run_presentation()
        # the error came out only after the dictionary step it overlapped had finished
        assert steps == ["learnt"]
    finally:
        exp.close()


def test_the_coder_learns_from_chunks_as_from_their_batch(tiny_overrides) -> None:
    cfg = compose(tiny_overrides)
    first = Experiment(cfg)
    second = Experiment(cfg)
    try:
        rng = np.random.default_rng(0)
        references = rng.integers(0, 256, (3, 64, 64, 3), dtype=np.uint8)
        images = rng.integers(0, 256, (3, 64, 64, 3), dtype=np.uint8)
        for exp in (first, second):
            exp.coder.set_reference(references)
        whole = first.coder(images, learn=True)
        chunks = [
            second.coder.encode(images[:2], slice(0, 2)),
            second.coder.encode(images[2:], slice(2, 3)),
        ]
        second.coder.learn_from(chunks)
        assert torch.equal(whole.state, torch.cat([c.output.state for c in chunks]))
        assert torch.equal(whole.reward, torch.cat([c.output.reward for c in chunks]))
        for name, dictionary in first.coder.dictionaries.items():
            assert torch.equal(dictionary, second.coder.dictionaries[name]), name
        assert not torch.equal(
            first.coder.dictionaries["coarse"], Experiment(cfg).coder.dictionaries["coarse"]
        )
    finally:
        first.close()
        second.close()


def test_a_frozen_coder_config_keeps_its_dictionaries_in_training(tiny_overrides) -> None:
    exp = Experiment(compose(tiny_overrides + ["coder.learn=false"]))
    try:
        before = {name: d.clone() for name, d in exp.coder.dictionaries.items()}
        exp.run_presentation(learn=True)
        for name, dictionary in exp.coder.dictionaries.items():
            assert torch.equal(dictionary, before[name]), name
        assert exp.policy.updates.item() > 0  # the policy still learnt
    finally:
        exp.close()


def test_frames_rendered_from_any_thread_are_the_same(tiny_overrides) -> None:
    exp = Experiment(compose(tiny_overrides))
    try:
        physics = exp.envs[0].physics
        exp.envs[0].reset()
        here = physics.render_left_eye()
        elsewhere: list[np.ndarray] = []
        worker = threading.Thread(target=lambda: elsewhere.append(physics.render_left_eye()))
        worker.start()
        worker.join()
        np.testing.assert_array_equal(elsewhere[0], here)
        assert here.std() > 0  # a real picture, not a blank buffer
    finally:
        exp.close()


def test_an_error_on_the_gl_thread_reaches_the_caller() -> None:
    import parallax.envs

    def fail() -> None:
        raise ValueError("from the GL thread")

    with pytest.raises(ValueError, match="from the GL thread"):
        parallax.envs.gl_thread().call(fail)
    assert parallax.envs.gl_thread().call(lambda: 7) == 7  # and it goes on serving
