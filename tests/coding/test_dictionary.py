"""Dictionary, gradient step and per-scale outputs (paper §3.3, eqs. 3–4)."""

from __future__ import annotations

import torch

from parallax.coding.dictionary import (
    codes_times_residuals,
    gradient_step_,
    pooled_activity,
    random_dictionary,
    reconstruction_error,
)
from parallax.coding.pursuit import matching_pursuit


def _generator(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def test_random_dictionary_is_unit_norm_and_reproducible() -> None:
    first = random_dictionary(288, 200, _generator(0))
    assert first.shape == (288, 200) and first.dtype == torch.float32
    torch.testing.assert_close(first.norm(dim=1), torch.ones(288))
    assert torch.equal(first, random_dictionary(288, 200, _generator(0)))
    assert not torch.equal(first, random_dictionary(288, 200, _generator(1)))


def test_grouped_codes_times_residuals_equals_the_dense_product() -> None:
    dictionary = random_dictionary(40, 30, _generator(1), dtype=torch.float64)
    patches = torch.randn(120, 30, generator=_generator(2), dtype=torch.float64)
    code = matching_pursuit(patches, dictionary, sparsity=7)
    expected = code.codes.T @ code.residuals
    torch.testing.assert_close(codes_times_residuals(code, 40), expected)


def test_gradient_step_follows_eq_and_keeps_unit_atoms() -> None:
    dictionary = random_dictionary(40, 30, _generator(3), dtype=torch.float64)
    patches = torch.randn(120, 30, generator=_generator(4), dtype=torch.float64)
    code = matching_pursuit(patches, dictionary, sparsity=5)
    expected = dictionary + 0.1 * code.codes.T @ code.residuals / 120
    expected = expected / expected.norm(dim=1, keepdim=True)
    updated = dictionary.clone()
    gradient_step_(updated, code, learning_rate=0.1)
    torch.testing.assert_close(updated, expected)
    # With the codes held fixed, a small step lowers the reconstruction error it descends.
    before = (patches - code.codes @ dictionary).square().sum()
    small = dictionary.clone()
    gradient_step_(small, code, learning_rate=0.01)
    assert (patches - code.codes @ small).square().sum() < before


def test_pooled_activity_is_the_mean_squared_coefficient() -> None:
    codes = torch.tensor([[[1.0, 0.0, -2.0], [3.0, 0.0, 0.0]]])
    torch.testing.assert_close(pooled_activity(codes), torch.tensor([[5.0, 0.0, 2.0]]))


def test_reconstruction_error_is_relative_and_zero_patches_count_zero() -> None:
    patches = torch.tensor([[[3.0, 4.0], [0.0, 0.0], [1.0, 0.0]]])
    residuals = torch.tensor([[[0.0, 5.0], [0.0, 0.0], [0.5, 0.0]]])
    error = reconstruction_error(patches, residuals)
    torch.testing.assert_close(error, torch.tensor([(1.0 + 0.0 + 0.25) / 3]))
    assert torch.isfinite(error).all()


def test_cpu_radix_grouping_matches_the_torch_sort_used_elsewhere() -> None:
    from parallax.coding.reference import stable_order

    picks = torch.randint(0, 288, (5000,), generator=_generator(5))
    fast = stable_order(picks, 288)  # numpy int16 radix sort on the CPU
    general = stable_order(picks, 40_000)  # torch's stable argsort (any device)
    assert torch.equal(fast, general)
    assert torch.equal(picks[fast], torch.sort(picks, stable=True).values)


def test_a_sum_of_robots_steps_is_one_step_per_image_of_its_own_patches() -> None:
    # images=B: the step is η·Bᵀ·R/P per image of P patches, summed over the B images, i.e. B
    # times the mean step before renormalisation; images=1 is the mean step itself.
    dictionary = random_dictionary(40, 30, _generator(5), dtype=torch.float64)
    patches = torch.randn(3 * 50, 30, generator=_generator(6), dtype=torch.float64)
    code = matching_pursuit(patches, dictionary, sparsity=5)
    summed, mean, scaled = dictionary.clone(), dictionary.clone(), dictionary.clone()
    gradient_step_(summed, code, learning_rate=0.1, images=3)
    gradient_step_(mean, code, learning_rate=0.1)
    gradient_step_(scaled, code, learning_rate=0.3)
    torch.testing.assert_close(summed, scaled)
    assert not torch.allclose(summed, mean)
    expected = dictionary + 0.1 * sum(
        code.codes[i * 50 : (i + 1) * 50].T @ code.residuals[i * 50 : (i + 1) * 50] / 50
        for i in range(3)
    )
    torch.testing.assert_close(summed, expected / expected.norm(dim=1, keepdim=True))
