"""The geometric distance estimator: 1/d linear in tan q_p, fitted to the learner's queue."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from parallax.config import compose, validate
from parallax.distance import DistanceLearner
from parallax.distance.estimators import ESTIMATORS
from parallax.distance.estimators.geometric import Geometric

LATERAL = [0.05, 0.1, 0.15, 0.2]


def pursuit_pans(distance: float, wobble: float = 0.0) -> list[float]:
    """The pans (deg) of an eye that holds the panel's centre from each lateral position."""
    return [math.degrees(math.atan(l / distance)) + wobble for l in LATERAL]


def learner(**settings) -> DistanceLearner:
    return DistanceLearner(
        LATERAL, seed=0, queue_size=6, hidden=3, estimator="geometric", **settings
    )


def test_it_is_found_by_its_name_and_the_config_accepts_it():
    assert ESTIMATORS["geometric"] is Geometric
    validate(compose(["experiment=geometric_multi_5_20_weighted"]))
    validate(compose(["distance.estimator=geometric"]))


def test_pans_that_hold_the_panel_give_its_distance_up_to_the_ridge():
    fitted = learner()
    for d in (3.0, 4.5, 6.0, 7.5, 9.0, 10.0):
        fitted.observe(pursuit_pans(d), d)
    assert fitted.is_ready
    unseen = np.array([pursuit_pans(d) for d in (3.3, 5.1, 8.8)])
    np.testing.assert_allclose(fitted.predict(unseen), [3.3, 5.1, 8.8], rtol=1e-4)


def test_its_answers_stay_within_the_queues_distances():
    fitted = learner()
    for d in (3.0, 4.5, 6.0, 7.5, 9.0, 10.0):
        fitted.observe(pursuit_pans(d), d)
    # an eye that turned the wrong way, and one that turned far too far
    runaway = np.array([[-0.5, -1.0, -1.5, -2.0], pursuit_pans(1.0)])
    np.testing.assert_array_equal(fitted.predict(runaway), [10.0, 3.0])


def test_it_refits_when_the_queue_changes_and_keeps_the_tensor_type():
    fitted = learner()
    for d in (3.0, 4.5, 6.0, 7.5, 9.0, 10.0):  # a constant offset of 0.05° on every pan
        fitted.observe(pursuit_pans(d, wobble=0.05), d)
    s = torch.tensor([pursuit_pans(5.0, wobble=0.05)], dtype=torch.float64)
    before = fitted.predict(s)
    assert before.dtype == torch.float64 and before.shape == (1,)
    fitted.observe(pursuit_pans(4.0), 5.5)  # a wrong target moves the line
    assert fitted.estimator.fitted_at == fitted.observations - 1  # not refitted yet
    after = fitted.predict(s)
    assert fitted.estimator.fitted_at == fitted.observations
    assert float(after) != pytest.approx(float(before), rel=1e-6)


def test_the_network_is_fitted_all_the_same():
    geometric, network = learner(), DistanceLearner(LATERAL, seed=0, queue_size=6, hidden=3)
    for d in (3.0, 4.5, 6.0, 7.5, 9.0, 10.0):
        stats = geometric.observe(pursuit_pans(d), d)
        assert stats == network.observe(pursuit_pans(d), d) or math.isnan(stats["loss"])
    for name, value in network.network.state_dict().items():
        assert torch.equal(value, geometric.network.state_dict()[name]), name
