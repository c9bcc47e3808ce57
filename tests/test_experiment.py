"""The lockstep (parallax.lockstep) behind Experiment.run_presentation: the worlds step on the GL
thread while the coder works, robots are encoded chunk by chunk, the dictionary step runs on the
coder's helper thread, and none of it changes a number."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import torch

from parallax import lockstep, loop
from parallax.config import compose
from parallax.executor import InOrder
from parallax.experiment import Experiment
from parallax.readouts import READOUTS
from parallax.routes import Chosen


def _in_order(exp: Experiment) -> InOrder:
    """The plain sequence on this thread, for ``exp``'s robots and turns."""
    return InOrder(exp.envs, exp.coder, exp.turns)


def _presentations(overrides: list[str], chunk: int, monkeypatch, count: int = 2):
    """``count`` presentations of a fresh experiment encoding ``chunk`` robots at a time, the
    robot slices of its encodings, and the state of its coder and policy afterwards."""
    monkeypatch.setattr(lockstep, "ENCODE_CHUNK", chunk)
    exp = Experiment(compose(overrides))
    slices = []
    encode_frame = exp.coder.encode_frame

    def recording_encode_frame(images, robots=slice(None)):  # I(t), not θ_ref's I0
        slices.append((robots.start, robots.stop))
        return encode_frame(images, robots)

    monkeypatch.setattr(exp.coder, "encode_frame", recording_encode_frame)
    try:
        presentations = [exp.run_presentation() for _ in range(count)]
        return presentations, slices, exp.coder.state_dict(), exp.policy.state_dict()
    finally:
        exp.close()


def _assert_same_states(first: dict, second: dict) -> None:
    assert first.keys() == second.keys()
    for name, value in first.items():
        if isinstance(value, torch.Tensor):
            assert torch.equal(value, second[name]), name


def _assert_same_presentation(a, b) -> None:
    for field in ("pans", "targets", "start_pans", "distances", "textures"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    for readout in READOUTS.values():
        np.testing.assert_array_equal(a.read(readout), b.read(readout), err_msg=readout.name)
    assert a.reward == b.reward and a.errors == b.errors and a.policy_stats == b.policy_stats
    assert a.steps == b.steps and a.route == b.route


def _assert_same(first, second) -> None:
    (presentations_a, _, coder_a, policy_a), (presentations_b, _, coder_b, policy_b) = first, second
    for a, b in zip(presentations_a, presentations_b, strict=True):
        _assert_same_presentation(a, b)
    _assert_same_states(coder_a, coder_b)
    _assert_same_states(policy_a, policy_b)


@pytest.mark.parametrize("extra", [[], ["policy.feature_norm=difference"]])
def test_robots_encoded_chunk_by_chunk_give_the_numbers_of_one_batch(
    tiny_overrides, extra, monkeypatch
) -> None:
    overrides = tiny_overrides + ["env.robots=3", "env.initial_pan_jitter_deg=1", *extra]
    one_batch = _presentations(overrides, 3, monkeypatch)
    assert set(one_batch[1]) == {(0, 3)}
    by_one = _presentations(overrides, 1, monkeypatch)
    assert set(by_one[1]) == {(0, 1), (1, 2), (2, 3)}
    _assert_same(by_one, one_batch)
    by_two = _presentations(overrides, 2, monkeypatch)
    assert by_two[1][:2] == [(0, 2), (2, 3)]  # chunks of 2 and 1, in robot order
    _assert_same(by_two, one_batch)


@pytest.mark.parametrize(
    ("robots", "extra"),
    [
        (1, []),
        (3, ["policy.feature_norm=difference", "policy.eye_position_reference_m=0.5"]),
        (3, ["policy.robot_updates=mean", "coder.robot_updates=mean"]),
        # turns of 2 and 1 robots (the first encoded in one chunk), and of one robot each
        (3, ["env.robots_per_turn=2", "policy.eye_position_reference_m=0.5"]),
        (3, ["env.robots_per_turn=1", "policy.robot_updates=mean"]),
        (2, ["policy.learn_reset_step=true"]),
    ],
)
def test_the_lockstep_gives_the_numbers_of_the_plain_loop(
    tiny_overrides, robots, extra, monkeypatch
) -> None:
    # the lockstep: GL thread, chunks of 2, the dictionary step on the helper thread during the
    # policy's turn; the plain sequence (parallax.executor.InOrder): everything on this thread
    monkeypatch.setattr(lockstep, "ENCODE_CHUNK", 2)
    cfg = compose(tiny_overrides + [f"env.robots={robots}", "env.initial_pan_jitter_deg=1", *extra])
    scheduled, plain = Experiment(cfg), Experiment(cfg)
    try:
        for learn in (True, True, False):
            presentation = scheduled.run_presentation(learn=learn)
            reference = loop.presentation(plain.parts, _in_order(plain), learn=learn)
            _assert_same_presentation(presentation, reference)
            # the loop's thread accounts for its waits in the lockstep, not for the plain loop
            assert list(presentation.waits) == list(lockstep.WAITS)
            assert all(seconds >= 0 for seconds in presentation.waits.values())
            assert presentation.waits["encoding"] > 0
        assert len(set(reference.pans.ravel().tolist())) > 1  # the robots moved
        _assert_same_states(scheduled.coder.state_dict(), plain.coder.state_dict())
        _assert_same_states(scheduled.policy.state_dict(), plain.policy.state_dict())
        assert scheduled.policy.updates.item() > 0
    finally:
        scheduled.close()
        plain.close()


def test_a_route_gives_the_numbers_of_the_plain_loop(tiny_overrides) -> None:
    """A route the loop asks "where next?" (here: the last position of L, then the first)."""
    cfg = compose(tiny_overrides + ["curriculum=multi_5_10"])
    scheduled, plain = Experiment(cfg), Experiment(cfg)

    def choose(visited, so_far):
        chosen = [len(so_far.lateral_positions) - 1, 0, None][len(visited)]
        if visited:  # the trial just ended is in the record, q_p of the position visited
            assert np.isfinite(so_far.pans[0, visited[-1]])
        return chosen

    route = Chosen(choose)

    try:
        for _ in range(2):
            presentation = scheduled.run_presentation(route=route)
            in_order = loop.presentation(plain.parts, _in_order(plain), route=route)
            _assert_same_presentation(presentation, in_order)
            assert presentation.route == [len(presentation.lateral_positions) - 1, 0]
        _assert_same_states(scheduled.coder.state_dict(), plain.coder.state_dict())
        _assert_same_states(scheduled.policy.state_dict(), plain.policy.state_dict())
    finally:
        scheduled.close()
        plain.close()


@pytest.mark.parametrize(
    ("per_turn", "batches"), [(0, [5]), (2, [2, 2, 1]), (4, [4, 1]), (1, [1] * 5)]
)
def test_each_turn_of_robots_learns_and_acts_before_the_next(
    tiny_overrides, per_turn, batches
) -> None:
    cfg = compose(tiny_overrides + ["env.robots=5", f"env.robots_per_turn={per_turn}"])
    exp = Experiment(cfg)
    calls = []
    update, act = exp.policy.update, exp.policy.act

    def recording_update(phi, *rest):
        calls.append(("update", phi.shape[0]))
        return update(phi, *rest)

    def recording_act(phi, greedy=False):
        calls.append(("act", phi.shape[0]))
        return act(phi, greedy=greedy)

    exp.policy.update, exp.policy.act = recording_update, recording_act
    try:
        presentation = exp.run_presentation()
    finally:
        exp.close()
    # the first iteration acts without a transition to learn from; then each turn's robots
    # learn from their step, then act, turn after turn
    assert calls[: len(batches)] == [("act", size) for size in batches]
    one_iteration = [call for size in batches for call in (("update", size), ("act", size))]
    assert calls[len(batches) : 3 * len(batches)] == one_iteration
    assert presentation.steps == exp.trial_length * len(exp.lateral_positions)


def test_one_robot_learns_the_same_whichever_way_robots_updates_combine(
    tiny_overrides, monkeypatch
) -> None:
    overrides = tiny_overrides + ["env.initial_pan_jitter_deg=1"]
    mean = ["policy.robot_updates=mean", "coder.robot_updates=mean"]
    _assert_same(
        _presentations(overrides + mean, 2, monkeypatch),
        _presentations(overrides, 2, monkeypatch),
    )


def test_an_error_during_the_step_waits_for_the_dictionary_step(
    tiny_overrides, monkeypatch
) -> None:
    exp = Experiment(compose(tiny_overrides))
    try:
        steps = []
        start_learning = exp.coder.learn_from_async

        class SlowSteps:
            """The dictionary step, finishing 0.2 s late."""

            def __init__(self, encodings) -> None:
                self.running = start_learning(encodings)

            def result(self) -> None:
                threading.Event().wait(0.2)
                self.running.result()
                steps.append("learnt")

        def failing_act(*_args, **_kwargs):
            raise RuntimeError("policy failed")

        monkeypatch.setattr(exp.coder, "learn_from_async", SlowSteps)
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


class _TimeStep:
    def __init__(self, image: np.ndarray) -> None:
        scalars = dict.fromkeys(("pan", "target_pan", "distance", "lateral_position"), 0.0)
        indices = dict.fromkeys(("position_index", "iteration", "texture_index"), 0)
        self.observation = {"reference": image, "image": image, **scalars, **indices}

    def last(self) -> bool:
        return False


class _RecordingCoder:
    """Stands in for the coder on a device of the given type; records the robots of each call."""

    def __init__(self, device: str) -> None:
        self.device = torch.device(device)
        self.calls: list[tuple[int, int]] = []

    def encode_frame(self, images, robots):
        from parallax.coding import CoderOutput, Encoding

        self.calls.append((robots.start, robots.stop))
        count = images.shape[0]
        output = CoderOutput(state=torch.zeros(count, 2), reward=torch.zeros(count), errors={})
        return Encoding(output=output, codes={})


@pytest.mark.parametrize(("device", "calls"), [("cpu", 4), ("meta", 1)])
def test_frames_are_encoded_in_chunks_on_the_cpu_and_in_one_call_on_a_gpu(device, calls) -> None:
    # on a GPU a call costs its kernel launches whatever it holds, so one call takes all B robots
    # (the meta device stands in for a GPU: the frames are stacked there, nothing is computed)
    from concurrent.futures import Future

    robots = 4 * lockstep.ENCODE_CHUNK
    futures = []
    for _ in range(robots):
        future: Future = Future()
        future.set_result(_TimeStep(np.zeros((8, 8, 3), dtype=np.uint8)))
        futures.append(future)
    coder = _RecordingCoder(device)
    seen, encodings = lockstep.Lockstep([], coder, [])._encode_as_they_arrive(futures)
    assert len(coder.calls) == calls == len(encodings)
    assert coder.calls[0][0] == 0 and coder.calls[-1][1] == robots
    assert len(seen) == sum(e.output.state.shape[0] for e in encodings) == robots


@pytest.mark.parametrize("learn_reset_step", [False, True])
def test_the_step_across_a_trials_reset_is_learnt_only_when_asked(tiny_overrides, learn_reset_step):
    """A presentation of r trials of t_h iterations gives r·(t_h − 1) transitions within trials;
    learning the step into each trial after the first adds r − 1."""
    cfg = compose(tiny_overrides + [f"policy.learn_reset_step={learn_reset_step}"])
    exp = Experiment(cfg)
    try:
        exp.run_presentation()
        trials, length = len(exp.lateral_positions), exp.trial_length
        within = trials * (length - 1)
        want = within + (trials - 1 if learn_reset_step else 0)
        assert exp.policy.updates.item() + exp.policy.rejected_updates.item() == want
    finally:
        exp.close()
