"""The movement planner (parallax.distance.planner) on synthetic sweeps from the geometry: a pan
q_k = atan(l_k / (d + 0.065)) in degrees, plus Gaussian noise, rounded to the 0.05° of the action
grid, for distances 3.0–10.0 m. Checks the weighted least-squares fit of 1/d and its
leave-one-out errors against explicit refits, the estimate's use of the visited order, where the
planner moves and when it stops at different prices, its state and its argument checks."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from parallax.distance.planner import BIN_EDGES_M, MovementPlanner

LATERAL = (0.05, 0.10, 0.15, 0.20)
GRID = np.round(np.arange(3.0, 10.0 + 1e-9, 0.1), 1)
EYE_OFFSET_M = 0.065


def synthetic(count, noise_deg, seed, lateral=LATERAL):
    """``count`` sweeps (pans in degrees, one per position of ``lateral``) and their distances;
    ``noise_deg``: the noise's standard deviation, one for all positions or one per position."""
    rng = np.random.default_rng(seed)
    distances = rng.choice(GRID, count)
    pans = np.degrees(np.arctan(np.asarray(lateral) / (distances[:, None] + EYE_OFFSET_M)))
    pans = pans + rng.normal(size=pans.shape) * np.asarray(noise_deg)
    return np.round(pans / 0.05) * 0.05, distances


def planner_for(noise_deg=0.02, seed=0, count=200, price_per_trial=0.0, **kwargs):
    planner = MovementPlanner(LATERAL, queue_size=count, price_per_trial=price_per_trial, **kwargs)
    for s, d in zip(*synthetic(count, noise_deg, seed)):
        planner.observe(s, d)
    assert planner.is_ready
    return planner


def design(planner, visited):
    """The fit's rows: the pans at the sorted ``visited`` positions, then 1."""
    columns = sorted(visited)
    return np.concatenate([planner.inputs[:, columns], np.ones((planner.distances.size, 1))], 1)


def weighted_lstsq(x, d):
    """Weights of 1/d on the rows of ``x``, least squares weighted by d²."""
    root = d[:, None]  # sqrt(d²)
    return np.linalg.lstsq(x * root, (1.0 / d) * d, rcond=None)[0]


@pytest.fixture(scope="module")
def planner():
    return planner_for()


@pytest.fixture(scope="module")
def held_out_sweeps():
    return synthetic(12, 0.02, seed=99)


# --- the fit ------------------------------------------------------------------------------------
def test_the_full_fit_reproduces_the_inverse_distance(planner):
    fit = planner.fit(range(len(LATERAL)))
    predicted = design(planner, range(len(LATERAL))) @ fit.weights
    relative = np.abs(predicted * planner.distances - 1.0)
    assert np.median(relative) < 0.01 and relative.max() < 0.05
    # the weights are those of the weighted least squares (the ridge is negligible)
    expected = weighted_lstsq(design(planner, range(len(LATERAL))), planner.distances)
    np.testing.assert_allclose(fit.weights, expected, rtol=1e-4)


def test_a_one_position_fit_is_about_proportional_to_its_pan(planner):
    # a pan is nearly degrees(l / d): 1/d ≈ q·π/180 / l, with a small intercept
    slope, intercept = planner.fit([3]).weights
    assert slope == pytest.approx(np.radians(1.0) / LATERAL[3], rel=0.1)
    assert abs(intercept) < 0.02


@pytest.mark.parametrize("visited", [[0], [3], [1, 3], [0, 1, 2, 3]], ids=str)
def test_leave_one_out_errors_are_those_of_refitting_without_the_row(visited):
    planner = planner_for(count=60, seed=3, ridge=0.0)
    fit = planner.fit(visited)
    x, d = design(planner, visited), planner.distances
    for i in (0, 7, 31, 59):
        keep = np.arange(d.size) != i
        weights = weighted_lstsq(x[keep], d[keep])
        estimate = 1.0 / (x[i] @ weights)
        assert fit.loo_estimates[i] == pytest.approx(estimate, rel=1e-9)
        assert fit.loo_errors_pct[i] == pytest.approx(100 * abs(estimate - d[i]) / d[i], abs=1e-7)


def test_leave_one_out_errors_exceed_the_in_sample_errors_on_average(planner):
    fit = planner.fit([0, 2])
    in_sample = 100 * np.abs(1.0 / (design(planner, [0, 2]) @ fit.weights) / planner.distances - 1)
    assert fit.loo_errors_pct.mean() > in_sample.mean()


def test_the_fit_is_cached_until_the_queue_changes():
    planner = planner_for(count=20)
    first = planner.fit([2, 0])
    assert planner.fit([0, 2]) is first  # the same subset in any order
    planner.observe(*[v[0] for v in synthetic(1, 0.02, seed=5)])
    assert planner.fit([0, 2]) is not first
    assert not np.array_equal(planner.fit([0, 2]).weights, first.weights)


# --- the estimate ---------------------------------------------------------------------------------
def test_the_estimate_reads_the_pans_in_the_visited_order(planner, held_out_sweeps):
    s = held_out_sweeps[0][0]
    weights = planner.fit([0, 3]).weights
    by_hand = 1.0 / (weights @ [s[0], s[3], 1.0])
    assert planner.estimate([3, 0], [s[3], s[0]]) == pytest.approx(by_hand, rel=1e-12)
    assert planner.estimate([0, 3], [s[0], s[3]]) == pytest.approx(by_hand, rel=1e-12)
    # the pans are matched to the positions: swapped, they give another distance
    assert planner.estimate([3, 0], [s[0], s[3]]) != pytest.approx(by_hand, rel=1e-3)


def test_three_positions_in_any_order_give_one_estimate(planner, held_out_sweeps):
    s = held_out_sweeps[0][3]
    estimates = {
        round(planner.estimate(list(order), s[list(order)]), 12)
        for order in itertools.permutations([0, 2, 3])
    }
    assert len(estimates) == 1


def test_a_full_plan_estimates_within_a_few_percent(planner, held_out_sweeps):
    errors = []
    for s, d in zip(*held_out_sweeps):
        visited, estimate = planner.plan(s)
        assert estimate == pytest.approx(planner.estimate(visited, s[visited]), rel=1e-12)
        errors.append(100 * abs(estimate - d) / d)
    # the rounding to 0.05° alone is ±2 % of a 1.1° pan at 10 m
    assert max(errors) < 5.0 and np.mean(errors) < 2.0


def test_the_expected_error_is_the_mean_leave_one_out_error_in_the_estimates_bin(planner):
    near = 5.5
    loo = planner.fit([3]).loo_estimates
    same = np.digitize(loo, BIN_EDGES_M) == np.digitize([near], BIN_EDGES_M)[0]
    assert 0 < same.sum() < same.size
    errors = planner.fit([1, 3]).loo_errors_pct
    assert planner.expected_error([1, 3], [3], near) == pytest.approx(errors[same].mean())
    # without a present estimate: over all rows
    assert planner.expected_error([1, 3]) == pytest.approx(errors.mean())
    assert planner.expected_error([1, 3], [3], None) == pytest.approx(errors.mean())


def test_the_expected_error_falls_back_to_all_rows_when_the_bin_is_empty():
    planner = MovementPlanner(LATERAL, queue_size=40)
    pans, distances = synthetic(200, 0.0, seed=4)
    far = distances >= 7.0
    for s, d in list(zip(pans[far], distances[far]))[:40]:
        planner.observe(s, d)
    assert planner.is_ready and (planner.fit([3]).loo_estimates > BIN_EDGES_M[0]).all()
    errors = planner.fit([2, 3]).loo_errors_pct
    assert planner.expected_error([2, 3], [3], 3.2) == pytest.approx(errors.mean())


# --- where to move and when to stop -------------------------------------------------------------
def test_with_no_price_the_planner_moves_while_it_helps(planner, held_out_sweeps):
    lengths = []
    for s in held_out_sweeps[0]:
        visited, _ = planner.plan(s)
        lengths.append(len(visited))
        # each step it took lowered the expected error near the estimate it had then
        for n in range(1, len(visited)):
            before = visited[:n]
            near = planner.estimate(before, s[before])
            assert planner.expected_error(visited[: n + 1], before, near) < (
                planner.expected_error(before, before, near)
            )
        # and where it stopped, no further position would have lowered it
        near = planner.estimate(visited, s[visited])
        now = planner.expected_error(visited, visited, near)
        for k in set(range(len(LATERAL))) - set(visited):
            assert planner.expected_error([*visited, k], visited, near) >= now
    assert min(lengths) >= 2 and max(lengths) == len(LATERAL)


def test_with_a_huge_price_per_trial_it_stops_after_one_position(held_out_sweeps):
    planner = planner_for(price_per_trial=1.0e6)
    for s in held_out_sweeps[0]:
        visited, _ = planner.plan(s)
        assert visited == [len(LATERAL) - 1]


def test_a_price_per_trial_shortens_the_routes(planner, held_out_sweeps):
    cheap = planner_for(price_per_trial=0.0)
    dear = planner_for(price_per_trial=0.3)
    cheap_lengths = [len(cheap.plan(s)[0]) for s in held_out_sweeps[0]]
    dear_lengths = [len(dear.plan(s)[0]) for s in held_out_sweeps[0]]
    assert all(a >= b for a, b in zip(cheap_lengths, dear_lengths))
    assert sum(dear_lengths) < sum(cheap_lengths)


def test_with_more_noise_at_small_l_the_first_position_is_the_largest_l():
    planner = planner_for(noise_deg=[0.3, 0.2, 0.1, 0.05], seed=1)
    assert planner.next_position([], []) == len(LATERAL) - 1
    singles = [planner.expected_error([k]) for k in range(len(LATERAL))]
    assert singles == sorted(singles, reverse=True)


def test_a_price_per_cm_makes_it_prefer_smaller_l(held_out_sweeps):
    free = planner_for(price_per_cm=0.0)
    dear = planner_for(price_per_cm=1.0)
    assert free.next_position([], []) == len(LATERAL) - 1
    assert dear.next_position([], []) == 0
    for s in held_out_sweeps[0]:
        free_route, dear_route = free.plan(s)[0], dear.plan(s)[0]
        assert max(dear_route) < max(free_route)
        assert dear_route == [0]


def test_the_price_counts_trials_and_the_travel_out_and_back():
    planner = MovementPlanner(LATERAL, queue_size=2, price_per_trial=0.5, price_per_cm=0.01)
    assert planner.price([]) == 0.0
    assert planner.price([1]) == pytest.approx(0.5 + 0.01 * 2 * 10)
    assert planner.price([3, 0]) == pytest.approx(2 * 0.5 + 0.01 * 2 * 20)


def test_next_position_never_revisits_and_stops_when_all_are_visited(planner, held_out_sweeps):
    rng = np.random.default_rng(7)
    s = held_out_sweeps[0][5]
    for size in range(len(LATERAL)):
        for _ in range(4):
            visited = [int(k) for k in rng.permutation(len(LATERAL))[:size]]
            chosen = planner.next_position(visited, s[visited])
            assert chosen is None or (chosen not in visited and 0 <= chosen < len(LATERAL))
    everything = [2, 0, 3, 1]
    assert planner.next_position(everything, s[everything]) is None


def test_a_plan_visits_each_position_at_most_once(planner, held_out_sweeps):
    for s in held_out_sweeps[0]:
        visited, _ = planner.plan(s)
        assert 1 <= len(visited) == len(set(visited)) <= len(LATERAL)


# --- the queue and the state ----------------------------------------------------------------------
def test_is_ready_after_queue_size_observations_and_keeps_the_newest():
    planner = MovementPlanner(LATERAL, queue_size=5)
    pans, distances = synthetic(7, 0.02, seed=2)
    for n, (s, d) in enumerate(zip(pans, distances), start=1):
        planner.observe(s, d)
        assert planner.is_ready == (n >= 5)
        assert planner.distances.size == min(n, 5)
    np.testing.assert_array_equal(planner.inputs, pans[::-1][:5])
    np.testing.assert_array_equal(planner.distances, distances[::-1][:5])


def test_a_state_dict_round_trip_gives_identical_plans(planner, held_out_sweeps):
    copy = MovementPlanner(
        LATERAL, queue_size=planner.queue_size, price_per_trial=planner.price_per_trial
    )
    copy.load_state_dict(planner.state_dict())
    assert copy.is_ready
    for s in held_out_sweeps[0]:
        assert copy.plan(s) == planner.plan(s)
    # the state is a copy both ways: writing into it changes neither planner
    state = planner.state_dict()
    fresh = MovementPlanner(LATERAL, queue_size=planner.queue_size)
    fresh.load_state_dict(state)
    before = fresh.plan(held_out_sweeps[0][0])
    state["inputs"][:] = 0.0
    state["distances"][:] = 1.0
    assert fresh.plan(held_out_sweeps[0][0]) == before
    assert planner.inputs.any() and (planner.distances != 1.0).any()


def test_a_state_for_another_lateral_list_is_refused(planner):
    other = MovementPlanner(LATERAL[:3], queue_size=planner.queue_size)
    with pytest.raises(ValueError, match="positions"):
        other.load_state_dict(planner.state_dict())


@pytest.mark.parametrize("ridge", [-1e-6, float("nan")], ids=str)
def test_a_bad_ridge_raises_value_error(ridge):
    # L, the queue's length and the prices are settings, checked by parallax.config
    # (tests/config/test_bad_input.py); the ridge is the planner's own
    with pytest.raises(ValueError, match="ridge"):
        MovementPlanner(LATERAL, ridge=ridge)


@pytest.mark.parametrize(
    "s, distance",
    [
        ([0.1, 0.2, 0.3], 5.0),
        ([0.1, 0.2, 0.3, 0.4, 0.5], 5.0),
        ([0.1, float("nan"), 0.3, 0.4], 5.0),
        ([0.1, 0.2, 0.3, 0.4], 0.0),
        ([0.1, 0.2, 0.3, 0.4], -3.0),
        ([0.1, 0.2, 0.3, 0.4], float("nan")),
    ],
    ids=str,
)
def test_a_bad_sweep_is_refused(s, distance):
    planner = MovementPlanner(LATERAL, queue_size=3)
    with pytest.raises(ValueError):
        planner.observe(s, distance)
    assert planner.distances.size == 0
