"""Paired differences over seeds and samples with a bootstrap interval (reports' comparisons)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parallax.tools.report.paired import paired_difference, seed_means, seeds_needed


def synthetic_runs(effect: float, seeds: int, samples: int, generator) -> tuple[list, list]:
    """Errors of two settings on the same samples: a shared per-seed level and per-sample
    difficulty (what pairing removes), and the setting's effect plus noise."""
    a, b = [], []
    for _ in range(seeds):
        level = generator.normal(10.0, 3.0)
        difficulty = generator.gamma(2.0, 2.0, samples)
        b.append(level + difficulty + generator.normal(0.0, 0.5, samples))
        a.append(level + difficulty + effect + generator.normal(0.0, 0.5, samples))
    return a, b


def test_a_known_difference_is_inside_the_interval_and_told_apart():
    a, b = synthetic_runs(-1.0, seeds=5, samples=71, generator=np.random.default_rng(0))
    result = paired_difference(a, b)
    assert result.low < -1.0 < result.high
    assert result.high < 0.0 and result.tells_apart and result.verdict == "a lower"
    assert result.seeds == 5 and result.samples == 5 * 71
    assert result.mean == pytest.approx(np.mean(seed_means(a, b)))


def test_no_difference_is_not_told_apart_and_the_interval_covers_zero():
    a, b = synthetic_runs(0.0, seeds=5, samples=71, generator=np.random.default_rng(1))
    result = paired_difference(a, b)
    assert result.low < 0.0 < result.high
    assert not result.tells_apart and result.verdict == "not told apart"


def test_the_interval_is_about_95_percent_over_many_synthetic_studies():
    generator = np.random.default_rng(2)
    covered = 0
    for _ in range(60):
        a, b = synthetic_runs(0.7, seeds=8, samples=30, generator=generator)
        result = paired_difference(a, b, resamples=400, seed=int(generator.integers(1 << 30)))
        covered += result.low <= 0.7 <= result.high
    assert covered >= 48  # a percentile bootstrap over 8 seeds is a little narrow, not wild


def test_same_inputs_same_interval_and_pairs_must_match():
    a, b = synthetic_runs(0.5, seeds=3, samples=10, generator=np.random.default_rng(3))
    assert paired_difference(a, b) == paired_difference(a, b)
    with pytest.raises(ValueError, match="paired"):
        paired_difference([a[0]], [b[0][:-1]])
    with pytest.raises(ValueError, match="seeds"):
        paired_difference(a, b[:2])
    one = paired_difference(a[:1], b[:1])
    assert one.seeds == 1 and math.isnan(one.low) and one.verdict == "one seed: no interval"
    assert math.isnan(paired_difference([], []).mean)


def test_seeds_needed_grows_as_the_effect_shrinks_against_the_spread():
    assert seeds_needed([1.0, 1.2, 0.8, 1.1]) == 2
    small = seeds_needed([0.1, -0.3, 0.4, 0.2, -0.1])
    assert small is not None and small > 10
    assert seeds_needed([0.5]) is None and seeds_needed([0.0, 0.0]) is None


def test_seeds_needed_counts_the_photographs_noise_and_more_than_the_seeds_that_did_not_tell():
    """Three seeds whose means agree, each over noisy photographs: the seeds' spread alone says
    two seeds; the interval, which covers the photographs too, does not tell the difference from
    zero, so more than three are needed, as many as the interval's spread implies."""
    rng = np.random.default_rng(1)
    noise = [rng.normal(0.0, 5.0, 71) for _ in range(3)]
    a = [(n - n.mean() + 0.3).tolist() for n in noise]  # each seed's mean difference is 0.3
    b = [[0.0] * 71 for _ in range(3)]
    difference = paired_difference(a, b)
    assert not difference.tells_apart
    assert seeds_needed(seed_means(a, b)) == 2  # the seeds' spread alone
    needed = seeds_needed(seed_means(a, b), difference)
    sigma = (difference.high - difference.low) / 2 / 1.96 * math.sqrt(3)
    assert needed == math.ceil((2.80 * sigma / 0.3) ** 2) and needed > 3
