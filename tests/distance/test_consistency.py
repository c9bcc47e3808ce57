"""Beyond the paper (§3.5): fits that leave out queued s vectors disagreeing with their neighbours."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from parallax.distance import DistanceLearner
from parallax.distance.consistency import consistent_mask, neighbour_deviation
from parallax.tools.analysis.synthetic_pans import PAPER_LATERAL_POSITIONS_M, paper_regression


def runaway_stream(count: int, runaway_share: float, seed: int):
    """The paper's regression with our runs' typical 0.3° pursuit error, and a share of s vectors
    replaced by runaways (4–6° off at every position, one sign per vector), as our runs show them."""
    rng = np.random.default_rng(seed)
    pans, distances = paper_regression(count, rng, noise_deg=0.3)
    runaway = rng.random(count) < runaway_share
    offsets = rng.uniform(4, 6, count) * rng.choice([-1.0, 1.0], count)
    pans = pans + np.where(runaway, offsets, 0.0)[:, None]
    return pans, distances, runaway


def test_runaways_are_found_and_ordinary_vectors_kept():
    pans, distances, runaway = runaway_stream(100, 0.15, seed=0)
    mask = consistent_mask(torch.as_tensor(pans), torch.as_tensor(distances), mads=3.0).numpy()
    assert runaway.sum() >= 8
    assert not mask[runaway].any()  # every runaway left out
    assert mask[~runaway].mean() > 0.9  # few ordinary vectors lost


def test_small_or_uniform_queues_are_used_whole():
    pans, distances, _ = runaway_stream(9, 0.5, seed=1)
    assert consistent_mask(
        torch.as_tensor(pans), torch.as_tensor(distances), 3.0, neighbours=8
    ).all()
    same = torch.ones(30, 4)
    assert consistent_mask(same, torch.linspace(3, 10, 30), 3.0).all()


def test_a_vector_is_not_its_own_neighbour():
    inputs = torch.tensor([[0.0], [0.0], [0.0], [9.0]], dtype=torch.float64)
    targets = torch.tensor([3.0, 3.0, 3.0, 3.0], dtype=torch.float64)
    deviation = neighbour_deviation(inputs, targets, neighbours=3)
    assert deviation.tolist() == [0.0, 0.0, 0.0, 9.0]


def test_the_learner_fits_without_the_runaways_in_its_queue():
    pans, distances, runaway = runaway_stream(140, 0.15, seed=2)
    learner = DistanceLearner(
        PAPER_LATERAL_POSITIONS_M,
        queue_size=100,
        hidden=30,
        initial_epochs=60,
        seed=0,
        outlier_mads=3.0,
    )
    stats = [learner.observe(s, d) for s, d in zip(pans, distances)]
    queued_runaways = int(runaway[-100:].sum())
    assert queued_runaways >= 8
    assert queued_runaways <= stats[-1]["outliers"] <= queued_runaways + 10
    # the fit ignored them: the network's error on the runaways is far above its error elsewhere
    errors = np.abs(learner.predict(pans[-100:]) - distances[-100:])
    assert np.median(errors[runaway[-100:]]) > 3 * np.median(errors[~runaway[-100:]])
    paper = DistanceLearner(
        PAPER_LATERAL_POSITIONS_M, queue_size=100, hidden=30, initial_epochs=60, seed=0
    )
    assert [paper.observe(s, d) for s, d in zip(pans, distances)][-1]["outliers"] == 0


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"outlier_mads": 0}, "outlier_mads must be a positive number"),
        ({"outlier_mads": float("nan")}, "outlier_mads must be a positive number"),
        ({"outlier_mads": 3, "outlier_neighbours": 1}, "outlier_neighbours must be an integer ≥ 2"),
    ],
)
def test_bad_settings_raise_one_line_errors(settings, message):
    with pytest.raises(ValueError, match=message):
        DistanceLearner([0.05, 0.1], **settings)
