"""python -m parallax.tools.analysis.continuous: the pursuit gain, and stopping a sweep early."""

from __future__ import annotations

import numpy as np
import pytest

from parallax.distance.planner import MovementPlanner
from parallax.tools.analysis.continuous import fixed_stop, main, planned_stop, pursuit_gain

LATERAL = np.round(np.arange(0.05, 0.205, 0.01), 2)


def _sweeps(count, noise_deg, seed=0):
    rng = np.random.default_rng(seed)
    distances = rng.choice(np.round(np.arange(30, 101) / 10, 1), size=count)
    pans = np.degrees(np.arctan(LATERAL[None] / distances[:, None]))
    return pans + rng.normal(0, noise_deg, pans.shape), distances


def test_the_gain_of_a_perfect_pursuit_is_the_nearness():
    pans, distances = _sweeps(20, 0.0)
    np.testing.assert_allclose(pursuit_gain(pans, LATERAL), 1 / distances, rtol=1e-12)


def _planner():
    planner = MovementPlanner(list(LATERAL), queue_size=300, price_per_trial=0.0)
    for s, d in zip(*_sweeps(300, 0.1, seed=1)):
        planner.observe(s, float(d))
    return planner


def test_a_higher_price_of_travel_stops_sooner_and_a_longer_sweep_errs_less():
    planner = _planner()
    pans, distances = _sweeps(60, 0.1, seed=2)
    free, _ = planned_stop(planner, pans, 0.0)
    dear, _ = planned_stop(planner, pans, 10.0)
    assert np.all(dear == 0) and free.mean() > 5
    short, near = fixed_stop(planner, pans, 0)
    full, far = fixed_stop(planner, pans, len(LATERAL) - 1)
    assert np.all(short == 0) and np.all(full == len(LATERAL) - 1)
    relative = lambda est: np.mean(np.abs(est - distances) / distances)  # noqa: E731
    assert relative(far) < 0.5 * relative(near)


def test_a_folder_without_an_evaluation_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main([str(tmp_path)])
    assert stop.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_an_error_that_follows_the_distance_is_learnable_and_noise_is_not():
    from parallax.tools.analysis.continuous import eye_error_parts
    from parallax.tools.analysis.eye_bound import perfect_pans

    distances = np.round(np.arange(30, 101) / 10, 1)
    perfect = perfect_pans(tuple(LATERAL), tuple(distances))
    bias = 0.05 + 0.01 * distances[:, None]  # the eye stops short, more so far away

    def result(pans):
        return {
            "readout": "last",
            "greedy_samples": {"grid": {"distances": list(distances)}},
            "greedy_samples_by_readout": {"last": {"grid": {"pans": pans.tolist()}}},
        }

    smooth = eye_error_parts(result(perfect - bias), LATERAL)
    assert smooth["eye_mae_deg"] > 0.1 and smooth["eye_unlearnable_deg"] < 1e-9
    noise = np.random.default_rng(0).normal(0, 0.05, perfect.shape)
    noisy = eye_error_parts(result(perfect + noise), LATERAL)
    assert noisy["eye_unlearnable_deg"] > 0.8 * noisy["eye_mae_deg"] > 0.03
