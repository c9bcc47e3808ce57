"""Matching pursuit (paper §3.3, eq. 1): plain MP, batched in Gram form."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.linear_model import orthogonal_mp

from parallax.coding.dictionary import random_dictionary
from parallax.coding.pursuit import dense_codes, matching_pursuit, matching_pursuit_recompute

K, N, SPARSITY = 200, 288, 10




def _unit_rows(rows: int, dim: int, seed: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    vectors = torch.randn(rows, dim, generator=torch.Generator().manual_seed(seed), dtype=dtype)
    return vectors / vectors.norm(dim=1, keepdim=True)


def _per_patch_reference(patch: np.ndarray, dictionary: np.ndarray, sparsity: int):
    """Textbook MP, one patch at a time: correlations of the residual recomputed every step."""
    residual = patch.copy()
    codes = np.zeros(dictionary.shape[0])
    for _ in range(sparsity):
        correlations = dictionary @ residual
        best = int(np.argmax(np.abs(correlations)))
        codes[best] += correlations[best]
        residual = residual - correlations[best] * dictionary[best]
    return codes, residual


def test_batched_pursuit_equals_the_per_patch_loop_on_random_dictionaries() -> None:
    dictionary = _unit_rows(N, K, seed=0)
    patches = _unit_rows(60, K, seed=1) * 1.4
    for code in (matching_pursuit(patches, dictionary, SPARSITY),
                 matching_pursuit_recompute(patches, dictionary, SPARSITY)):
        for row in range(patches.shape[0]):
            codes, residual = _per_patch_reference(patches[row].numpy(), dictionary.numpy(), SPARSITY)
            np.testing.assert_allclose(code.codes[row].numpy(), codes, atol=1e-5)
            np.testing.assert_allclose(code.residuals[row].numpy(), residual, atol=1e-5)


def test_float32_gram_form_agrees_with_recomputed_correlations() -> None:
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(2))
    patches = _unit_rows(300, K, seed=3, dtype=torch.float32)
    gram_form = matching_pursuit(patches, dictionary, SPARSITY)
    recomputed = matching_pursuit_recompute(patches, dictionary, SPARSITY)
    same_picks = (gram_form.atom_indices == recomputed.atom_indices).all(dim=1)
    assert same_picks.float().mean() > 0.97   # float32 near-ties may flip a rare late pick
    torch.testing.assert_close(gram_form.codes[same_picks], recomputed.codes[same_picks], atol=1e-5, rtol=0)


def test_residual_norm_never_increases() -> None:
    dictionary = _unit_rows(64, 50, seed=4, dtype=torch.float32)
    patches = _unit_rows(100, 50, seed=5, dtype=torch.float32)
    code = matching_pursuit(patches, dictionary, sparsity=25)
    previous = patches.norm(dim=1)
    for steps in range(1, 26):
        partial = dense_codes(code.atom_indices[:, :steps], code.coefficients[:, :steps], 64)
        norm = (patches - partial @ dictionary).norm(dim=1)
        assert (norm <= previous + 1e-5).all(), f"residual grew at step {steps}"
        previous = norm
    assert (previous < 0.9 * patches.norm(dim=1)).all()


def test_atoms_may_be_picked_again_and_their_coefficients_accumulate() -> None:
    dictionary = _unit_rows(20, 8, seed=6, dtype=torch.float64)   # overcomplete in 8-D
    patches = _unit_rows(200, 8, seed=7, dtype=torch.float64)
    code = matching_pursuit(patches, dictionary, sparsity=12)
    repeated = [row for row in range(200) if code.atom_indices[row].unique().numel() < 12]
    assert repeated, "with 12 steps in 8 dimensions some atom must come back"
    row = repeated[0]
    manual = torch.zeros(20, dtype=torch.float64)
    for atom, coefficient in zip(code.atom_indices[row], code.coefficients[row]):
        manual[atom] += coefficient
    torch.testing.assert_close(code.codes[row], manual)


def test_orthonormal_dictionary_recovers_sparse_codes_exactly_like_omp() -> None:
    rng = np.random.default_rng(8)
    basis, _ = np.linalg.qr(rng.standard_normal((K, K)))
    dictionary = torch.from_numpy(basis.T.copy())              # rows orthonormal
    true_codes = np.zeros((40, K))
    for row in range(40):
        support = rng.choice(K, size=SPARSITY, replace=False)
        true_codes[row, support] = rng.uniform(0.5, 2.0, SPARSITY) * rng.choice([-1, 1], SPARSITY)
    patches = torch.from_numpy(true_codes @ basis.T)
    code = matching_pursuit(patches, dictionary, SPARSITY)
    np.testing.assert_allclose(code.codes.numpy(), true_codes, atol=1e-10)
    assert code.residuals.abs().max() < 1e-10
    omp = orthogonal_mp(basis, patches.numpy().T, n_nonzero_coefs=SPARSITY).T
    np.testing.assert_allclose(code.codes.numpy(), omp, atol=1e-10)


def test_orthonormal_dictionary_keeps_the_k_largest_coefficients_of_a_dense_signal_like_omp() -> None:
    rng = np.random.default_rng(9)
    basis, _ = np.linalg.qr(rng.standard_normal((K, K)))
    patches = torch.from_numpy(rng.standard_normal((30, K)))
    code = matching_pursuit(patches, torch.from_numpy(basis.T.copy()), SPARSITY)
    omp = orthogonal_mp(basis, patches.numpy().T, n_nonzero_coefs=SPARSITY).T
    np.testing.assert_allclose(code.codes.numpy(), omp, atol=1e-10)


def test_zero_patches_give_zero_codes_and_residuals() -> None:
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(10))
    code = matching_pursuit(torch.zeros(5, K), dictionary, SPARSITY)
    assert torch.equal(code.codes, torch.zeros(5, N))
    assert torch.equal(code.residuals, torch.zeros(5, K))


def test_mismatched_shapes_and_bad_sparsity_are_refused() -> None:
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(11))
    with pytest.raises(ValueError, match="disagree"):
        matching_pursuit(torch.zeros(3, K + 1), dictionary, SPARSITY)
    with pytest.raises(ValueError, match="sparsity"):
        matching_pursuit(torch.zeros(3, K), dictionary, 0)
    with pytest.raises(ValueError, match="dtype"):
        matching_pursuit(torch.zeros(3, K, dtype=torch.float64), dictionary, SPARSITY)


def test_cpu_and_device_agnostic_steps_agree() -> None:
    from parallax.coding.pursuit import _gram_steps, _gram_steps_cpu, gram_matrix

    dictionary = _unit_rows(N, K, seed=12)
    correlations = _unit_rows(50, K, seed=13) @ dictionary.T
    gram = gram_matrix(dictionary)
    picks_cpu, coefficients_cpu = _gram_steps_cpu(correlations.clone(), gram, SPARSITY)
    picks_any, coefficients_any = _gram_steps(correlations.clone(), gram, SPARSITY)
    assert torch.equal(picks_cpu, picks_any)
    torch.testing.assert_close(coefficients_cpu, coefficients_any)
