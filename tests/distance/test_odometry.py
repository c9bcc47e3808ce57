"""Odometry targets (parallax.distance.targets.OdometryTargets): strides × the nominal stride,
bad readings refused, the truth a perfect learner would answer; distance.fit_from (the first fit
once the queue holds fit_from vectors); learn_online with unlabelled rows (predicted, not
queued); and the error statistics scored against truths in another unit than the panels'."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from parallax.distance import (
    TARGET_SOURCES,
    DistanceLearner,
    OdometryTargets,
    SupervisorTargets,
    distance_error_by_range,
)
from parallax.distance.online import learn_online
from parallax.distance.targets import make_target_source
from parallax.metrics import DistanceErrorTracker
from parallax.tools.evaluate import distance_results

LATERAL = [0.05, 0.1]
S = torch.tensor([2.0, 4.0], dtype=torch.float64)


def odometry_learner(queue_size=5, fit_from=None, nominal=0.05, **overrides) -> DistanceLearner:
    settings = dict(
        lateral_positions=LATERAL,
        queue_size=queue_size,
        hidden=3,
        epochs_per_call=2,
        initial_epochs=5,
        seed=0,
        targets="odometry",
        odometry={"walk_fraction": 1.0, "nominal_stride_m": nominal},
        fit_from=fit_from,
    )
    settings.update(overrides)
    return DistanceLearner(**settings)


def pans_for(distances) -> np.ndarray:
    """Eye-movement vectors that shrink with distance, like the real ones (degrees)."""
    d = np.asarray(distances, dtype=np.float64)[:, None]
    return np.degrees(np.arctan(np.asarray(LATERAL)[None, :] / d))


# -- the target source ---------------------------------------------------------------------------
def test_odometry_targets_are_strides_times_the_nominal_stride():
    source = OdometryTargets(nominal_stride_m=0.04)
    assert source(S, 100.0) == pytest.approx(4.0)
    assert source(S, 62.5) == pytest.approx(2.5)
    assert OdometryTargets()(S, 60.0) == pytest.approx(3.0)  # 5 cm strides by default
    assert source.walks and not SupervisorTargets.walks


def test_the_truth_is_the_slip_free_reach_in_the_robots_unit():
    source = OdometryTargets(nominal_stride_m=0.04)
    # a grown body (true stride 5.5 cm) reaches a 5 m panel in 90 strides: 3.6 m to the robot
    assert source.truth(5.0, 90.0) == pytest.approx(3.6)
    assert SupervisorTargets().truth(5.0, 90.0) == 5.0


@pytest.mark.parametrize("reading", [0.0, -3.0, math.nan, math.inf])
def test_a_bad_stride_count_is_refused(reading):
    with pytest.raises(ValueError, match="stride count"):
        OdometryTargets()(S, reading)


def test_target_sources_are_found_by_name_with_their_options():
    assert TARGET_SOURCES["odometry"] is OdometryTargets
    assert TARGET_SOURCES["supervisor"] is SupervisorTargets
    source = make_target_source("odometry", {"walk_fraction": 0.25, "nominal_stride_m": 0.04})
    assert isinstance(source, OdometryTargets)
    assert (source.walk_fraction, source.nominal_stride_m) == (0.25, 0.04)
    # the supervisor takes no options: the odometry ones are not forced on it
    assert isinstance(make_target_source("supervisor", {"walk_fraction": 0.25}), SupervisorTargets)


def test_the_learner_queues_odometry_targets():
    learner = odometry_learner(nominal=0.04)
    learner.observe(S, 100.0)
    learner.observe(S * 2, 50.0)
    assert learner.queue.targets.tolist() == pytest.approx([2.0, 4.0])  # newest first
    with pytest.raises(ValueError, match="stride count"):
        learner.observe(S, 0.0)


# -- fit_from ----------------------------------------------------------------------------------
@pytest.mark.parametrize("fit_from", [1, 2, 4])
def test_the_first_fit_comes_when_the_queue_holds_fit_from_vectors(fit_from):
    learner = odometry_learner(queue_size=5, fit_from=fit_from)
    distances = [3.0, 4.0, 5.0, 6.0, 7.0]
    for k, (s, d) in enumerate(zip(pans_for(distances), distances), start=1):
        stats = learner.observe(s, d / 0.05)
        assert stats["queue_fill"] == k
        assert stats["trained"] == float(k >= fit_from), k
        assert learner.is_ready == (k >= fit_from)
        assert learner.fits == max(0, k - fit_from + 1)
    prediction = learner.predict(pans_for([5.0]))
    assert np.all(np.isfinite(prediction))


def test_without_fit_from_the_first_fit_waits_for_a_full_queue():
    learner = odometry_learner(queue_size=3, fit_from=None)
    assert learner.fit_from == 3
    fits = [learner.observe(s, 80.0)["trained"] for s in pans_for([3.0, 4.0, 5.0])]
    assert fits == [0.0, 0.0, 1.0]


# -- learn_online with unlabelled rows ----------------------------------------------------------
def test_unlabelled_rows_are_predicted_but_not_queued():
    learner = odometry_learner(queue_size=6, fit_from=2)
    tracker = DistanceErrorTracker(window=50)
    pans = pans_for([3.0, 4.0, 5.0])
    truths = np.array([2.9, 3.9, 4.9])

    # not ready: nothing predicted; only the middle robot walked
    stats = learn_online(learner, tracker, pans, truths, [None, 78.0, None])
    assert stats["trained"] == 0.0 and stats["queue_fill"] == 1.0
    assert learner.queue.fill == 1 and not learner.is_ready and not tracker.pairs
    torch.testing.assert_close(learner.queue.inputs[0], torch.as_tensor(pans[1]))
    assert learner.queue.targets.tolist() == pytest.approx([78.0 * 0.05])

    # two more walks: three vectors, the fit (fit_from = 2) happens
    stats = learn_online(learner, tracker, pans, truths, [58.0, None, 98.0])
    assert stats["trained"] == 1.0 and learner.is_ready and not tracker.pairs
    assert learner.queue.fill == 3
    torch.testing.assert_close(learner.queue.inputs[0], torch.as_tensor(pans[2]))
    torch.testing.assert_close(learner.queue.inputs[1], torch.as_tensor(pans[0]))
    assert learner.queue.targets.tolist() == pytest.approx([98 * 0.05, 58 * 0.05, 78 * 0.05])

    # ready: every row is predicted against its truth, even with no walk at all; nothing learnt,
    # no statistics
    fits = learner.fits
    expected = np.asarray(learner.predict(pans), dtype=np.float64)
    assert learn_online(learner, tracker, pans, truths, [None, None, None]) == {}
    assert learner.queue.fill == 3 and learner.fits == fits
    assert [p for p, _ in tracker.pairs] == pytest.approx(expected.tolist())
    assert [t for _, t in tracker.pairs] == truths.tolist()

    # a walk again: predicted before it is learnt (three more pairs), then queued and fitted
    stats = learn_online(learner, tracker, pans, truths, [None, None, 80.0])
    assert len(tracker.pairs) == 6 and learner.queue.fill == 4 and stats["trained"] == 1.0


def test_without_readings_the_truths_are_the_targets():
    learner = DistanceLearner(
        lateral_positions=LATERAL, queue_size=4, hidden=3, initial_epochs=5, seed=0
    )
    tracker = DistanceErrorTracker()
    learn_online(learner, tracker, pans_for([3.0, 6.0]), np.array([3.0, 6.0]))
    assert learner.queue.targets.tolist() == [6.0, 3.0]


# -- scoring against truths in the robot's unit --------------------------------------------------
def test_error_ranges_follow_the_panel_distances_when_given():
    truths = np.array([4.95, 6.9, 9.0])  # e.g. a grown body's odometry truths
    panels = np.array([5.0, 7.0, 9.9])
    estimates = truths * np.array([1.1, 1.0, 0.8])
    by_truth = distance_error_by_range(estimates, truths)
    by_panel = distance_error_by_range(estimates, truths, at=panels)
    assert by_truth["3-4.9"] == pytest.approx(10.0) and by_truth["5-6.9"] == pytest.approx(0.0)
    assert math.isnan(by_panel["3-4.9"])
    assert by_panel["5-6.9"] == pytest.approx(10.0)
    assert by_panel["7-10"] == pytest.approx(10.0)  # (0 + 20) / 2
    assert by_panel["total"] == by_truth["total"] == pytest.approx(10.0)


class _Fixed:
    """A learner that answers the same for every s."""

    def __init__(self, answers):
        self.answers = np.asarray(answers, dtype=np.float64)

    def predict(self, pans):
        return self.answers[: len(pans)]


def test_distance_results_score_against_the_truths_and_report_mae():
    distances = np.array([5.0, 5.0, 8.0])
    truths = np.array([4.0, 4.0, 6.0])
    pans = pans_for(distances)
    result = distance_results(_Fixed([4.4, 4.0, 6.0]), pans, distances, truths)
    assert result["trials"] == 3
    assert result["mae_m"] == pytest.approx(0.4 / 3)
    assert result["by_range"]["5-6.9"] == pytest.approx(5.0)  # (10 + 0) / 2 % at the 5 m panels
    assert result["by_range"]["7-10"] == pytest.approx(0.0)
    assert set(result["per_distance"]) == {"5.00", "8.00"}
    assert result["samples"]["distances"] == distances.tolist()
    # without truths the distances are the truths
    plain = distance_results(_Fixed([5.5, 5.0, 8.0]), pans, distances)
    assert plain["mae_m"] == pytest.approx(0.5 / 3)
    assert plain["by_range"]["5-6.9"] == pytest.approx(5.0)
