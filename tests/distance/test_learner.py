"""Distance learner (paper §3.5–3.5.2): weighting, queue, scaling, targets, resume, config,
metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf

from parallax.config import DistanceConfig
from parallax.distance import (
    TARGET_SOURCES,
    DistanceLearner,
    DistanceMLP,
    QueueMemory,
    SupervisorTargets,
    distance_error_by_range,
    position_weights,
    sensitive_positions,
)
from parallax.geometry import disparity_score, effective_patch_size
from parallax.tools.analysis.synthetic_pans import (
    PAPER_DISTANCES_M,
    PAPER_LATERAL_POSITIONS_M,
    paper_regression,
    parallax_pans,
)

#: Plain Levenberg–Marquardt (trainlm): the numbers below are taken without the recipe's weight
#: decay.
TRAINLM = {"weight_decay": 0.0}
SMALL_L = [0.05, 0.10, 0.15, 0.20]


def small_learner(**overrides) -> DistanceLearner:
    settings = dict(
        lateral_positions=SMALL_L,
        queue_size=40,
        hidden=5,
        epochs_per_call=3,
        initial_epochs=20,
        seed=0,
        lm=TRAINLM,
    )
    settings.update(overrides)
    return DistanceLearner(**settings)


def feed(
    learner: DistanceLearner, pans: np.ndarray, distances: np.ndarray
) -> list[dict[str, float]]:
    return [learner.observe(s, d) for s, d in zip(pans, distances)]


# -- weighting, eqs. (10)–(12) ---------------------------------------------------------------------
def test_sensitive_positions_and_weights_for_the_paper_L():
    lateral_cm = list(range(5, 21))
    sensitive = sensitive_positions([cm / 100 for cm in lateral_cm])
    assert sensitive == [cm >= 15 for cm in lateral_cm]
    for y in (1.0, 2.5):
        weights = position_weights([cm / 100 for cm in lateral_cm], sensitive, y)
        expected = [1.0 / ((1 + 20 - cm) * y) if cm >= 15 else 1.0 for cm in lateral_cm]
        assert weights == pytest.approx(expected, rel=1e-12)
    assert weights[lateral_cm.index(15)] == pytest.approx(1 / (6 * 2.5))


def test_table_1_positions_and_the_tolerance_that_decides_them():
    table_1_cm = [5, 7, 10, 13, 15, 20]
    scores = [round(disparity_score(cm / 100)) for cm in table_1_cm]
    assert scores == [9, 12, 18, 23, 27, 35]
    assert effective_patch_size(10, 8) == pytest.approx(28.28, abs=0.01)
    assert sensitive_positions([cm / 100 for cm in table_1_cm]) == [False] * 4 + [True] * 2
    assert sensitive_positions([0.15], tolerance=1.5) == [False]  # strict ≥ P_e would miss 15 cm
    assert sensitive_positions([0.14], tolerance=3.6) == [True]


def test_every_position_after_a_sensitive_one_is_sensitive():
    assert sensitive_positions([0.05, 0.16, 0.06]) == [False, True, True]
    with pytest.raises(ValueError, match="2 sensitivity flags for 1 positions"):
        position_weights([0.05], [True, True], 1.0)


def test_learner_applies_the_weights_in_training_and_prediction():
    learner = small_learner()
    assert learner.sensitive == [False, False, True, True]
    assert learner.weights.tolist() == pytest.approx([1.0, 1.0, 1 / 6, 1.0])
    pans, distances = paper_regression(40, np.random.default_rng(0), lateral_positions_m=SMALL_L)
    feed(learner, pans, distances)
    with torch.no_grad():
        expected = learner.network(torch.from_numpy(pans) * learner.weights)
    np.testing.assert_array_equal(learner.predict(pans), expected.numpy())
    unweighted = small_learner(weighting=False)
    assert unweighted.weights.tolist() == [1.0] * 4


def test_per_input_scaling_cancels_the_weighting_and_global_and_no_scaling_keep_it():
    pans, distances = paper_regression(40, np.random.default_rng(2), lateral_positions_m=SMALL_L)
    probe = parallax_pans(SMALL_L, np.array([3.0, 6.5, 10.0]), 0.0, np.random.default_rng(0))
    predictions = {}
    for scaling in ("per_input", "global", "none"):
        for weighting in (True, False):
            learner = small_learner(input_scaling=scaling, weighting=weighting)
            feed(learner, pans, distances)
            predictions[scaling, weighting] = learner.predict(probe)
    np.testing.assert_allclose(
        predictions["per_input", True], predictions["per_input", False], rtol=1e-6
    )
    assert np.abs(predictions["global", True] - predictions["global", False]).max() > 1e-3
    # without input processing the weights reach the fit only through LM's damping: a change
    # all the same
    assert np.abs(predictions["none", True] - predictions["none", False]).max() > 1e-6


def test_no_input_scaling_starts_as_per_input_scaling_and_feeds_the_pans_as_they_are():
    """initnw over each input's range: a new network under "none" computes what the same
    weights compute behind a per-input mapminmax, and its inputs stay unscaled."""
    generator = torch.Generator().manual_seed(5)
    pans = torch.rand(30, 4, generator=generator, dtype=torch.float64) * 3 + 0.2
    targets = torch.rand(30, generator=generator, dtype=torch.float64) * 7 + 3
    networks = {}
    for scaling in ("per_input", "none"):
        networks[scaling] = DistanceMLP(4, 6, scaling, torch.Generator().manual_seed(9))
        networks[scaling].fit_scaling(pans, targets, preserve_function=False)
    torch.testing.assert_close(networks["none"](pans), networks["per_input"](pans))
    assert networks["none"].input_gain.tolist() == [1.0] * 4
    assert networks["none"].input_offset.tolist() == [0.0] * 4


# -- queue memory, eq. (9) -------------------------------------------------------------------------
def test_queue_is_fifo_with_s1_newest():
    queue = QueueMemory(capacity=3, input_size=2)
    for k in range(1, 6):
        queue.push(torch.tensor([k, -k], dtype=torch.float64), target=float(k))
        assert queue.fill == min(k, 3)
    assert queue.is_full
    assert queue.targets.tolist() == [5.0, 4.0, 3.0]  # s_1 newest … s_c oldest; 1 and 2 dequeued
    assert queue.matrix.tolist() == [[5.0, 4.0, 3.0], [-5.0, -4.0, -3.0]]
    with pytest.raises(ValueError, match="shape"):
        queue.push(torch.zeros(3), 1.0)


def test_training_starts_when_the_queue_is_full():
    learner = small_learner()
    pans, distances = paper_regression(42, np.random.default_rng(1), lateral_positions_m=SMALL_L)
    stats = feed(learner, pans, distances)
    assert [s["trained"] for s in stats] == [0.0] * 39 + [1.0] * 3
    assert [s["queue_fill"] for s in stats[:3]] == [1.0, 2.0, 3.0]
    assert all(math.isnan(s["loss"]) for s in stats[:39])
    assert stats[-1]["loss"] == pytest.approx(stats[-1]["rmse_m"] ** 2)
    assert 0 < stats[-1]["epochs"] <= 3 and stats[39]["epochs"] <= 20
    assert learner.is_ready
    assert learner.queue.targets[0].item() == distances[-1]
    with pytest.raises(RuntimeError, match="not ready"):
        small_learner().predict(pans)


def test_a_batch_of_vectors_is_queued_in_order_then_fitted_once():
    pans, distances = paper_regression(56, np.random.default_rng(2), lateral_positions_m=SMALL_L)
    one_by_one, batched = small_learner(), small_learner()
    feed(one_by_one, pans[:40], distances[:40])
    feed(batched, pans[:40], distances[:40])
    for start in (40, 48):  # two lockstep batches of B = 8 robots
        feed(one_by_one, pans[start : start + 8], distances[start : start + 8])
        stats = batched.observe_batch(pans[start : start + 8], distances[start : start + 8])
        assert stats["trained"] == 1.0
    assert torch.equal(batched.queue.inputs, one_by_one.queue.inputs)
    assert batched.fits == 3 and one_by_one.fits == 17 and batched.observations == 56
    # B = 1 is the paper's loop: observe_batch of one row is observe, bit for bit
    single, same = small_learner(), small_learner()
    for s, d in zip(pans, distances):
        single.observe(s, d)
        same.observe_batch(s[None, :], [d])
    for name, value in single.network.state_dict().items():
        assert torch.equal(same.network.state_dict()[name], value)
    with pytest.raises(ValueError, match="n distances"):
        same.observe_batch(pans[:3], distances[:2])


def test_learns_the_paper_regression():
    pans, distances = paper_regression(300, np.random.default_rng(0))
    learner = DistanceLearner(
        PAPER_LATERAL_POSITIONS_M, queue_size=300, hidden=30, initial_epochs=60, seed=0, lm=TRAINLM
    )
    stats = feed(learner, pans, distances)[-1]
    truth = np.repeat(PAPER_DISTANCES_M, 3)
    errors = distance_error_by_range(
        learner.predict(
            parallax_pans(PAPER_LATERAL_POSITIONS_M, truth, 0.05, np.random.default_rng(9))
        ),
        truth,
    )
    assert stats["trained"] == 1.0 and stats["rmse_m"] < 0.2
    assert errors["total"] < 3.0, errors  # ≈ 1 % here; the paper reports 1.3–2.7 %


# -- network scaling -------------------------------------------------------------------------------
def test_refitting_the_scaling_preserves_the_function():
    generator = torch.Generator().manual_seed(3)
    for scaling in ("global", "per_input", "none"):
        network = DistanceMLP(4, 6, input_scaling=scaling, generator=generator)
        first = torch.rand(50, 4, generator=generator, dtype=torch.float64) * 3
        network.fit_scaling(
            first, torch.rand(50, generator=generator, dtype=torch.float64) * 7 + 3, False
        )
        probe = torch.rand(20, 4, generator=generator, dtype=torch.float64) * 4
        before = network(probe).detach()
        network.fit_scaling(
            first * 1.7 + 0.3,
            torch.rand(50, generator=generator, dtype=torch.float64) * 2 + 5,
            True,
        )
        torch.testing.assert_close(network(probe).detach(), before, rtol=1e-10, atol=1e-10)


def test_all_zero_and_constant_inputs_stay_finite():
    learner = small_learner()
    distances = np.linspace(3.0, 10.0, 40)
    feed(learner, np.zeros((40, 4)), distances)
    assert all(torch.isfinite(p).all() for p in learner.network.parameters())
    assert np.isfinite(learner.predict(np.zeros(4)))
    other = small_learner()
    pans, _ = paper_regression(40, np.random.default_rng(4), lateral_positions_m=SMALL_L)
    pans[:, 1] = 0.7
    feed(other, pans, distances)
    assert np.isfinite(other.predict(np.zeros((2, 4)))).all()
    assert all(torch.isfinite(b).all() for b in other.network.buffers())


def test_bad_inputs_raise_clear_errors():
    learner = small_learner()
    with pytest.raises(ValueError, match="shape"):
        learner.observe(np.zeros(3), 5.0)
    with pytest.raises(ValueError, match="finite"):
        learner.observe(np.array([0.1, math.nan, 0.3, 0.4]), 5.0)
    with pytest.raises(ValueError, match="-1.0"):
        learner.observe(np.zeros(4), -1.0)
    with pytest.raises(TypeError, match="learning_rate"):  # a misspelt option of distance.lm
        small_learner(lm={"mu": 1e-3, "learning_rate": 0.1})


# -- targets, resume, config -----------------------------------------------------------------------
def test_target_sources_are_pluggable():
    class Halved(SupervisorTargets):  # a file of parallax/distance/targets/ is found by name
        name = "test_halved"

        def __call__(self, s, distance_m):
            return distance_m / 2

    TARGET_SOURCES[Halved.name] = Halved
    try:
        learner = small_learner(targets="test_halved")
        learner.observe(np.zeros(4), 8.0)
        assert learner.queue.targets.tolist() == [4.0]
    finally:
        del TARGET_SOURCES["test_halved"]
    assert "supervisor" in TARGET_SOURCES


def test_resume_continues_bit_identically():
    pans, distances = paper_regression(50, np.random.default_rng(5), lateral_positions_m=SMALL_L)
    straight = small_learner()
    feed(straight, pans, distances)
    first = small_learner()
    feed(first, pans[:44], distances[:44])
    resumed = small_learner(seed=123)  # a different initialisation, overwritten by the state
    resumed.load_state_dict(first.state_dict())
    stats = feed(resumed, pans[44:], distances[44:])
    assert stats[-1]["trained"] == 1.0
    for (name, a), b in zip(
        straight.network.state_dict().items(), resumed.network.state_dict().values()
    ):
        assert torch.equal(a, b), name
    assert torch.equal(straight.queue.inputs, resumed.queue.inputs)
    assert straight.optimizer.mu == resumed.optimizer.mu
    with pytest.raises(ValueError, match="state is for"):
        small_learner(queue_size=41).load_state_dict(first.state_dict())


def test_the_hydra_config_instantiates_the_learner():
    config = OmegaConf.structured(DistanceConfig)
    config.lateral_positions = PAPER_LATERAL_POSITIONS_M
    config.seed = 0
    learner = instantiate(config)
    assert isinstance(learner, DistanceLearner)
    assert learner.queue.capacity == 300 and learner.network.hidden_layer.out_features == 30
    assert learner.sensitive == [cm >= 15 for cm in range(5, 21)]


# -- the distance-error metric, Tables 4–5 ---------------------------------------------------------
def test_distance_error_by_range():
    truth = np.array([3.0, 4.95, 3.0 + 20 * 0.1, 6.9, 7.0, 10.0])
    estimate = truth * np.array([1.1, 0.9, 1.02, 0.98, 1.05, 1.05])
    errors = distance_error_by_range(estimate, truth)
    assert errors["3-4.9"] == pytest.approx(10.0)  # 4.95 m belongs to [3, 5)
    assert errors["5-6.9"] == pytest.approx(2.0)
    assert errors["7-10"] == pytest.approx(5.0)
    assert errors["total"] == pytest.approx(np.mean([10, 10, 2, 2, 5, 5]))
    assert math.isnan(distance_error_by_range([8.0], [7.5])["3-4.9"])
    with pytest.raises(ValueError, match="positive"):
        distance_error_by_range([1.0], [0.0])
    with pytest.raises(ValueError, match="equal length"):
        distance_error_by_range([1.0, 2.0], [3.0])


# -- MATLAB train's defaults: dividerand and the validation stop -------------------------------
def test_each_fit_splits_the_queue_as_dividerand_and_stops_on_validation():
    pans, distances = paper_regression(60, np.random.default_rng(7), lateral_positions_m=SMALL_L)
    matlab = dict(validation_fraction=0.15, test_fraction=0.15, epochs_per_call=1000)
    learner = small_learner(**matlab, initial_epochs=1000, reset_mu=True)
    train_rows, validation_rows = learner._split(40)
    assert (len(train_rows), len(validation_rows)) == (28, 6)  # 70 / 15 / 15 of 40
    assert not set(train_rows.tolist()) & set(validation_rows.tolist())
    stats = feed(learner, pans, distances)
    fitted = [s for s in stats if s["trained"]]
    assert len(fitted) == 21
    # a fit of up to 1000 epochs ends on the validation vectors (or at trainlm's other stops),
    # never on its epoch budget
    assert all(s["epochs"] < 1000 for s in fitted)
    assert sum(s["stopped_max_fail"] for s in fitted) > 0


@pytest.mark.parametrize("reset_mu", [True, False])
def test_reset_mu_starts_every_fit_from_lm_mu(reset_mu):
    """MATLAB's train starts each call from mu = 0.001: a μ left by the last fit then changes
    nothing; carried over, it does."""
    pans, distances = paper_regression(45, np.random.default_rng(8), lateral_positions_m=SMALL_L)
    learners = [small_learner(reset_mu=reset_mu) for _ in range(2)]
    for learner in learners:
        feed(learner, pans[:44], distances[:44])
    learners[1].optimizer.mu = 1e4  # as if the last fit had ended with a large μ
    for learner in learners:
        feed(learner, pans[44:], distances[44:])
    same = all(
        torch.equal(a, b)
        for a, b in zip(learners[0].network.parameters(), learners[1].network.parameters())
    )
    assert same == reset_mu


def test_the_split_stream_resumes_bit_identically():
    pans, distances = paper_regression(50, np.random.default_rng(5), lateral_positions_m=SMALL_L)
    matlab = dict(validation_fraction=0.15, test_fraction=0.15, max_fail=2, reset_mu=True)
    straight = small_learner(**matlab)
    feed(straight, pans, distances)
    first = small_learner(**matlab)
    feed(first, pans[:44], distances[:44])
    resumed = small_learner(**matlab, seed=123)
    resumed.load_state_dict(first.state_dict())
    feed(resumed, pans[44:], distances[44:])
    for (name, a), b in zip(
        straight.network.state_dict().items(), resumed.network.state_dict().values()
    ):
        assert torch.equal(a, b), name


@pytest.mark.parametrize("warm_start", [True, False])
def test_without_a_warm_start_each_fit_starts_from_new_weights(warm_start):
    """MATLAB's train called again on a network continues from its weights; a program that
    builds the network again before each call does not: the weights the last fit left then
    change nothing."""
    pans, distances = paper_regression(45, np.random.default_rng(8), lateral_positions_m=SMALL_L)
    learners = [small_learner(warm_start=warm_start) for _ in range(2)]
    for learner in learners:
        feed(learner, pans[:44], distances[:44])
    with torch.no_grad():  # as if the last fit had ended elsewhere
        learners[1].network.hidden_layer.weight.add_(0.5)
    for learner in learners:
        stats = feed(learner, pans[44:], distances[44:])
    same = all(
        torch.equal(a, b)
        for a, b in zip(learners[0].network.parameters(), learners[1].network.parameters())
    )
    assert same != warm_start
    # a fit from new weights gets the first fit's epochs (20), a warm one epochs_per_call (3)
    assert stats[-1]["epochs"] > 3 if not warm_start else stats[-1]["epochs"] <= 3


@pytest.mark.parametrize("keep_first_scaling", [True, False])
def test_a_warm_fit_keeps_the_first_scaling_only_when_asked(keep_first_scaling):
    """MATLAB's train configures mapminmax on its first call only; refitting the scaling to a
    queue whose range has grown changes it."""
    pans, distances = paper_regression(60, np.random.default_rng(3), lateral_positions_m=SMALL_L)
    learner = small_learner(keep_first_scaling=keep_first_scaling)
    feed(learner, pans[:40], distances[:40])
    assert learner.fits == 1
    first = {name: value.clone() for name, value in learner.network.named_buffers()}
    wider = pans[40:] * 3.0  # pans beyond the first queue's range
    feed(learner, wider, distances[40:])
    assert learner.fits == 21
    kept = {
        name: torch.equal(first[name], value) for name, value in learner.network.named_buffers()
    }
    assert all(kept.values()) if keep_first_scaling else not kept["input_gain"]


def test_new_weights_at_every_fit_resume_bit_identically():
    pans, distances = paper_regression(50, np.random.default_rng(5), lateral_positions_m=SMALL_L)
    straight = small_learner(warm_start=False)
    feed(straight, pans, distances)
    first = small_learner(warm_start=False)
    feed(first, pans[:44], distances[:44])
    resumed = small_learner(warm_start=False, seed=123)
    resumed.load_state_dict(first.state_dict())
    feed(resumed, pans[44:], distances[44:])
    for (name, a), b in zip(
        straight.network.state_dict().items(), resumed.network.state_dict().values()
    ):
        assert torch.equal(a, b), name


# -- the paper's probable scoring of Tables 4–5 ----------------------------------------------------
def test_queue_error_scores_the_network_on_the_vectors_of_its_own_queue():
    pans, distances = paper_regression(60, np.random.default_rng(4), lateral_positions_m=SMALL_L)
    learner = small_learner()
    feed(learner, pans[:39], distances[:39])
    assert learner.queue_error() == {}  # the queue of 40 is not full: no network yet
    feed(learner, pans[39:], distances[39:])
    # the queue holds the last 40 vectors, newest first
    kept_pans, kept_distances = pans[-40:][::-1], distances[-40:][::-1]
    expected = distance_error_by_range(learner.predict(kept_pans.copy()), kept_distances)
    assert learner.queue_error() == expected
    held_out = parallax_pans(SMALL_L, kept_distances, 0.0, np.random.default_rng(9))
    assert learner.queue_error() != distance_error_by_range(
        learner.predict(held_out), kept_distances
    )
