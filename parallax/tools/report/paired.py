"""Paired comparisons of two settings over seeds and photographs, with a 95 % interval.

Every comparison of the reports is paired: the two settings are run (or replayed) with the same
seeds and scored on the same samples (the same photographs at the same distances, or the same
queue), so each seed gives one difference per sample. The interval is a two-level percentile
bootstrap: the seeds are drawn with replacement, and within each drawn seed its samples are
drawn with replacement, so that the interval covers both what another seed and what other
photographs would give. A difference whose interval excludes zero tells the settings apart.

With few seeds the bootstrap's interval is too narrow rather than too wide (n = 3 seeds give at
most 10 distinct resamples of the top level), so a comparison also says how many seeds it rests
on, and :func:`seeds_needed` estimates how many would resolve an observed mean difference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

#: Resamples of the bootstrap, and its generator's seed: the same inputs give the same interval.
RESAMPLES = 10_000
BOOTSTRAP_SEED = 0


@dataclass(frozen=True)
class PairedDifference:
    """Mean of (a − b) over seeds (each seed's mean over its samples), its 95 % interval, the
    number of seeds, and whether the interval excludes zero."""

    mean: float
    low: float
    high: float
    seeds: int
    samples: int

    @property
    def tells_apart(self) -> bool:
        return self.seeds > 1 and (self.low > 0.0 or self.high < 0.0)

    @property
    def verdict(self) -> str:
        if self.seeds < 2:
            return "one seed: no interval"
        if not self.tells_apart:
            return "not told apart"
        return "a lower" if self.high < 0.0 else "a higher"

    def as_dict(self) -> dict:
        return {**asdict(self), "tells_apart": self.tells_apart}

    def format(self, unit: str = "") -> str:
        if not math.isfinite(self.mean):
            return "—"
        return (
            f"{self.mean:+.2f}{unit} [{self.low:+.2f}, {self.high:+.2f}] "
            f"(n={self.seeds}{', told apart' if self.tells_apart else ''})"
        )


def paired_difference(
    a: Sequence[Sequence[float]],
    b: Sequence[Sequence[float]],
    resamples: int = RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> PairedDifference:
    """a[i][j] and b[i][j]: the two settings' errors of seed i on its sample j (paired).

    Seeds may have different numbers of samples; a seed's two lists must be equally long.
    Non-finite pairs are left out. Returns the mean difference with its bootstrap interval
    (NaN with no seed).
    """
    if len(a) != len(b):
        raise ValueError(f"a has {len(a)} seeds and b {len(b)}: a paired comparison needs both")
    differences = []
    for index, (first, second) in enumerate(zip(a, b)):
        first, second = np.asarray(first, dtype=np.float64), np.asarray(second, dtype=np.float64)
        if first.shape != second.shape:
            raise ValueError(
                f"seed {index}: {first.size} samples against {second.size}: the samples are paired"
            )
        difference = first - second
        difference = difference[np.isfinite(difference)]
        if difference.size:
            differences.append(difference)
    if not differences:
        return PairedDifference(math.nan, math.nan, math.nan, 0, 0)
    mean = float(np.mean([d.mean() for d in differences]))
    samples = sum(d.size for d in differences)
    if len(differences) == 1:
        return PairedDifference(mean, math.nan, math.nan, 1, samples)
    generator = np.random.default_rng(seed)
    # the top level: which seed stands in each place of each resample; then, for each place,
    # that seed's samples drawn again
    chosen = generator.integers(0, len(differences), (resamples, len(differences)))
    means = np.empty(chosen.shape)
    for index, difference in enumerate(differences):
        places = chosen == index
        count = int(places.sum())
        if count:
            drawn = generator.integers(0, difference.size, (count, difference.size))
            means[places] = difference[drawn].mean(axis=1)
    draws = means.mean(axis=1)
    low, high = np.percentile(draws, [2.5, 97.5])
    return PairedDifference(mean, float(low), float(high), len(differences), samples)


def seed_means(a: Sequence[Sequence[float]], b: Sequence[Sequence[float]]) -> list[float]:
    """Each seed's mean difference (a − b) over its finite paired samples."""
    means = []
    for first, second in zip(a, b):
        difference = np.asarray(first, dtype=np.float64) - np.asarray(second, dtype=np.float64)
        difference = difference[np.isfinite(difference)]
        if difference.size:
            means.append(float(difference.mean()))
    return means


def seeds_needed(
    per_seed_differences: Sequence[float],
    difference: PairedDifference | None = None,
    power_z: float = 0.84,
) -> int | None:
    """Seeds a paired test would need to tell the observed mean difference from zero at the 5 %
    level with 80 % power: n = ((1.96 + 0.84)·σ / mean)², σ the spread of one seed's mean. σ is
    the larger of the seeds' own spread and the one the bootstrap's interval implies (its
    half-width / 1.96 × √n: a seed's mean also varies with its photographs, which a spread of
    few seeds' means can miss). A comparison not told apart with n seeds needs more than n.
    None when the mean is zero or there are fewer than two seeds to estimate a spread."""
    values = np.asarray(per_seed_differences, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size < 2 or values.mean() == 0.0:
        return None
    spread = float(values.std(ddof=1))
    fewest = 2
    if difference is not None and math.isfinite(difference.low) and difference.seeds > 1:
        half_width = (difference.high - difference.low) / 2
        spread = max(spread, half_width / 1.96 * math.sqrt(difference.seeds))
        if not difference.tells_apart:
            fewest = difference.seeds + 1
    if spread == 0.0:
        return fewest
    return max(fewest, math.ceil(((1.96 + power_z) * spread / abs(float(values.mean()))) ** 2))
