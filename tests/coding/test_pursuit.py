"""Matching pursuit (paper §3.3, eq. 1): plain MP, batched in Gram form."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.linear_model import orthogonal_mp

from parallax.coding.dictionary import random_dictionary
from parallax.coding.pursuit import gram_matrix, matching_pursuit, matching_pursuit_recompute
from parallax.coding.reference import dense_codes, gram_steps, gram_steps_cpu
from parallax.coding.retina import stack_pair

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
    for code in (
        matching_pursuit(patches, dictionary, SPARSITY),
        matching_pursuit_recompute(patches, dictionary, SPARSITY),
    ):
        for row in range(patches.shape[0]):
            codes, residual = _per_patch_reference(
                patches[row].numpy(), dictionary.numpy(), SPARSITY
            )
            np.testing.assert_allclose(code.codes[row].numpy(), codes, atol=1e-5)
            np.testing.assert_allclose(code.residuals[row].numpy(), residual, atol=1e-5)


def test_float32_gram_form_agrees_with_recomputed_correlations() -> None:
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(2))
    patches = _unit_rows(300, K, seed=3, dtype=torch.float32)
    gram_form = matching_pursuit(patches, dictionary, SPARSITY)
    recomputed = matching_pursuit_recompute(patches, dictionary, SPARSITY)
    same_picks = (gram_form.atom_indices == recomputed.atom_indices).all(dim=1)
    assert same_picks.float().mean() > 0.97  # float32 near-ties may flip a rare late pick
    torch.testing.assert_close(
        gram_form.codes[same_picks], recomputed.codes[same_picks], atol=1e-5, rtol=0
    )


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
    dictionary = _unit_rows(20, 8, seed=6, dtype=torch.float64)  # overcomplete in 8-D
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
    dictionary = torch.from_numpy(basis.T.copy())  # rows orthonormal
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


def test_orthonormal_dictionary_keeps_the_k_largest_coefficients_of_a_dense_signal_like_omp() -> (
    None
):
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


def test_mismatched_shapes_and_dtypes_are_refused() -> None:
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(11))
    with pytest.raises(ValueError, match="disagree"):
        matching_pursuit(torch.zeros(3, K + 1), dictionary, SPARSITY)
    with pytest.raises(ValueError, match="dtype"):
        matching_pursuit(torch.zeros(3, K, dtype=torch.float64), dictionary, SPARSITY)


def test_cpu_and_device_agnostic_steps_agree() -> None:
    dictionary = _unit_rows(N, K, seed=12)
    correlations = _unit_rows(50, K, seed=13) @ dictionary.T
    gram = gram_matrix(dictionary)
    picks_cpu, coefficients_cpu = gram_steps_cpu(correlations.clone(), gram, SPARSITY)
    picks_any, coefficients_any = gram_steps(correlations.clone(), gram, SPARSITY)
    assert torch.equal(picks_cpu, picks_any)
    torch.testing.assert_close(coefficients_cpu, coefficients_any)


# --- the compiled kernel (pursuit_kernel.cpp) against the numpy/torch loop -----------------------


def _compiler_missing() -> str | None:
    """Why the kernel cannot be built here at all (no C++ compiler or no ninja), else None."""
    import shutil

    from torch.utils import cpp_extension

    if not any(shutil.which(name) for name in ("c++", "g++", "clang++")):
        return "no C++ compiler on this machine"
    if not cpp_extension.is_ninja_available():
        return "the ninja package is not installed"
    return None


@pytest.fixture(scope="module")
def compiled():
    """The compiled kernels (built once per cache, then loaded)."""
    from parallax.coding import native

    missing = _compiler_missing()
    if missing:
        pytest.skip(f"the compiled pursuit kernels cannot be built: {missing}")
    module = native.load_kernels()
    assert module is not None, (
        f"the kernels failed to build or disagreed: {native.kernel_failure()}"
    )
    return module


def _both_steps(compiled, correlations: torch.Tensor, gram: torch.Tensor, sparsity: int):
    expected = gram_steps_cpu(correlations.clone(), gram, sparsity)
    got = compiled.gram_pursuit(correlations.clone(), gram, sparsity)
    return expected, got


def _realistic_patches(dtype: torch.dtype) -> torch.Tensor:
    """Normalised [I0 ; I(t)] patch pairs of a photograph at the coarse scale, as the coder
    makes them."""
    import skimage.data

    from parallax.coding.retina import ScaleSpec, as_gray_batch, prepare_reference, scale_patches

    spec = ScaleSpec(window=250, subsample=8, patch=10, stride=1)
    photo = skimage.data.astronaut()
    reference = as_gray_batch(photo[None, 100:356, 100:356])
    current = as_gray_batch(photo[None, 100:356, 96:352])
    pairs = stack_pair(
        prepare_reference(scale_patches(reference, spec), "per_half"),
        scale_patches(current, spec),
        "per_half",
    )
    return pairs.reshape(-1, spec.dim).to(dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize(
    "atoms", [N, 75, 37, 5]
)  # whole vector lanes, long and short tails, only a tail
def test_fused_kernel_is_bit_identical_to_the_torch_loop_on_random_data(
    compiled, dtype, atoms
) -> None:
    dictionary = _unit_rows(atoms, K, seed=20, dtype=dtype)
    correlations = _unit_rows(200, K, seed=21, dtype=dtype) @ dictionary.T
    (picks, coefficients), (fused_picks, fused_coefficients) = _both_steps(
        compiled, correlations, gram_matrix(dictionary), SPARSITY
    )
    assert fused_picks.dtype == torch.int64 and fused_coefficients.dtype == dtype
    assert torch.equal(fused_picks, picks)
    assert torch.equal(fused_coefficients, coefficients)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fused_kernel_is_bit_identical_on_normalised_photo_patches(compiled, dtype) -> None:
    patches = _realistic_patches(dtype)
    assert patches.shape == (529, K)
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(22), dtype=dtype)
    code_torch = matching_pursuit(patches, dictionary, SPARSITY, kernel="torch")
    code_fused = matching_pursuit(patches, dictionary, SPARSITY, kernel="cpp")
    for field in ("atom_indices", "coefficients", "codes", "residuals"):
        assert torch.equal(getattr(code_fused, field), getattr(code_torch, field)), field
    recomputed = matching_pursuit_recompute(patches, dictionary, SPARSITY)
    same_picks = (code_fused.atom_indices == recomputed.atom_indices).all(dim=1)
    assert same_picks.float().mean() > (0.97 if dtype == torch.float32 else 0.999)
    torch.testing.assert_close(
        code_fused.coefficients[same_picks],
        recomputed.coefficients[same_picks],
        rtol=1e-5,
        atol=1e-6,
    )


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fused_kernel_breaks_ties_like_numpy_argmax(compiled, dtype) -> None:
    # Every atom twice (rows 2i and 2i+1 equal): every correlation is tied with its twin, and
    # the first of the two must win, as numpy's argmax (and torch's) pick it.
    atoms = _unit_rows(N // 2, K, seed=23, dtype=dtype)
    dictionary = atoms.repeat_interleave(2, dim=0)
    correlations = _unit_rows(100, K, seed=24, dtype=dtype) @ dictionary.T
    (picks, coefficients), (fused_picks, fused_coefficients) = _both_steps(
        compiled, correlations, gram_matrix(dictionary), SPARSITY
    )
    assert torch.equal(fused_picks, picks) and torch.equal(fused_coefficients, coefficients)
    assert (picks[:, 0] % 2 == 0).all()
    # ±equal magnitudes, zero rows, a NaN and an infinity: numpy's argmax of |c| decides.
    values = torch.tensor([0.5, -0.5, 0.25], dtype=dtype)
    special = values[torch.randint(0, 3, (40, N), generator=torch.Generator().manual_seed(25))]
    special[1] = 0
    special[2, 100] = float("nan")
    special[3, 7] = float("-inf")
    special[4, N - 1] = 0.75  # the maximum in the tail after the last whole lane
    gram = torch.eye(N, dtype=dtype)
    (picks, coefficients), (fused_picks, fused_coefficients) = _both_steps(
        compiled, special, gram, 3
    )
    assert torch.equal(fused_picks, picks)
    torch.testing.assert_close(fused_coefficients, coefficients, equal_nan=True, rtol=0, atol=0)
    assert (
        fused_picks[1].tolist() == [0, 0, 0]
        and fused_picks[2, 0] == 100
        and fused_picks[4, 0] == N - 1
    )


def test_fused_kernels_refuse_bad_arguments(compiled) -> None:
    gram = torch.eye(8)
    with pytest.raises(RuntimeError, match="dtype"):
        compiled.gram_pursuit(torch.zeros(3, 8, dtype=torch.float64), gram, 2)
    with pytest.raises(RuntimeError, match=r"\(M, N\)"):
        compiled.gram_pursuit(torch.zeros(3, 7), gram, 2)
    with pytest.raises(RuntimeError, match="sparsity"):
        compiled.gram_pursuit(torch.zeros(3, 8), gram, 0)
    with pytest.raises(RuntimeError, match="contiguous"):
        compiled.gram_pursuit(torch.zeros(8, 3).T, gram, 2)
    picks, coefficients = torch.tensor([[0, 8]]), torch.ones(1, 2)
    with pytest.raises(RuntimeError, match="pick 8"):
        compiled.codes_and_residuals(torch.zeros(1, 5), torch.zeros(8, 5), picks, coefficients)
    with pytest.raises(RuntimeError, match="pick 8"):
        compiled.codes_times_residuals(picks, coefficients, torch.zeros(1, 5), 8)


def test_fused_kernels_give_the_torch_codes_residuals_and_gradient_bit_for_bit(compiled) -> None:
    from parallax.coding.dictionary import codes_times_residuals, gradient_step_

    for dtype in (torch.float32, torch.float64):
        dictionary = random_dictionary(N, K, torch.Generator().manual_seed(28), dtype=dtype)
        patches = torch.cat([_realistic_patches(dtype), torch.zeros(3, K, dtype=dtype)])
        codes = {
            kernel: matching_pursuit(patches, dictionary, SPARSITY, kernel=kernel)
            for kernel in ("torch", "cpp")
        }
        for field in ("atom_indices", "coefficients", "codes", "residuals"):
            assert torch.equal(getattr(codes["cpp"], field), getattr(codes["torch"], field)), field
        products = [
            codes_times_residuals(codes["torch"], N, kernel=kernel) for kernel in ("torch", "cpp")
        ]
        assert torch.equal(products[0], products[1])
        stepped = []
        for kernel in ("torch", "cpp"):
            copy = dictionary.clone()
            gradient_step_(copy, codes["torch"], 0.2, kernel=kernel)
            stepped.append(copy)
        assert torch.equal(stepped[0], stepped[1]) and not torch.equal(stepped[0], dictionary)


def test_the_gradient_of_chunks_of_patches_is_that_of_all_of_them_bit_for_bit(compiled) -> None:
    # A lockstep encodes its robots chunk by chunk and takes one dictionary step from all chunks.
    from parallax.coding.dictionary import codes_times_residuals, gradient_step_
    from parallax.coding.pursuit import SparseCode

    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(31))
    patches = _realistic_patches(torch.float32)
    chunks = [
        matching_pursuit(part, dictionary, SPARSITY)
        for part in (patches[:200], patches[200:201], patches[201:])
    ]
    whole = SparseCode(
        *(
            torch.cat([getattr(chunk, field) for chunk in chunks])
            for field in ("atom_indices", "coefficients", "codes", "residuals")
        )
    )
    for kernel in ("torch", "cpp"):
        assert torch.equal(
            codes_times_residuals(chunks, N, kernel=kernel),
            codes_times_residuals(whole, N, kernel=kernel),
        ), kernel
        stepped_whole, stepped_chunks = dictionary.clone(), dictionary.clone()
        gradient_step_(stepped_whole, whole, 0.2, kernel=kernel)
        gradient_step_(stepped_chunks, chunks, 0.2, kernel=kernel)
        assert torch.equal(stepped_chunks, stepped_whole), kernel


def test_the_one_call_dictionary_step_and_gram_are_the_separate_calls_bit_for_bit(
    compiled,
) -> None:
    # the coder's helper thread takes its step in one call, so that it never holds the GIL
    # between the step's parts (parallax.coding.dictionary.gradient_step_and_gram_)
    from parallax.coding.dictionary import gradient_step_, gradient_step_and_gram_
    from parallax.coding.pursuit import gram_matrix

    for dtype in (torch.float32, torch.float64):
        dictionary = random_dictionary(N, K, torch.Generator().manual_seed(33), dtype=dtype)
        patches = _realistic_patches(dtype)
        chunks = [
            matching_pursuit(part, dictionary, SPARSITY) for part in (patches[:150], patches[150:])
        ]
        for kernel in ("torch", "cpp"):
            separate, together = dictionary.clone(), dictionary.clone()
            gradient_step_(separate, chunks, 0.2, kernel=kernel, images=2)
            gram = gradient_step_and_gram_(together, chunks, 0.2, kernel=kernel, images=2)
            if kernel == "torch":  # the numpy/torch code takes its steps apart
                assert gram is None and torch.equal(together, dictionary)
                continue
            assert torch.equal(together, separate) and not torch.equal(together, dictionary)
            assert torch.equal(gram, gram_matrix(separate))
        assert gradient_step_and_gram_(dictionary.clone(), [], 0.2, kernel="cpp") is None


def test_theta_from_the_picks_is_torchs_theta_bit_for_bit_where_the_coder_uses_it(compiled) -> None:
    from parallax.coding.dictionary import (
        exact_pooled_activity_kernel,
        pooled_activity,
        pooled_activity_of,
    )

    patches = _realistic_patches(torch.float32)
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(32))
    assert exact_pooled_activity_kernel(
        patches.shape[0], N, SPARSITY, torch.float32
    )  # the paper's coarse scale
    sparse = matching_pursuit(patches, dictionary, SPARSITY, dense_codes=False)
    dense = matching_pursuit(patches, dictionary, SPARSITY)
    assert sparse.codes is None and torch.equal(sparse.residuals, dense.residuals)
    assert torch.equal(
        pooled_activity_of(sparse, 1, N), pooled_activity(dense.codes.reshape(1, -1, N))
    )


def test_half_precision_takes_the_torch_code_even_when_the_kernels_are_asked_for(compiled) -> None:
    from parallax.coding.dictionary import gradient_step_

    dictionary = random_dictionary(30, 20, torch.Generator().manual_seed(29), dtype=torch.float16)
    patches = torch.randn(7, 20, generator=torch.Generator().manual_seed(30)).half()
    asked, plain = (
        matching_pursuit(patches, dictionary, 4, kernel=kernel) for kernel in ("cpp", "torch")
    )
    assert torch.equal(asked.codes, plain.codes) and torch.equal(asked.residuals, plain.residuals)
    gradient_step_(dictionary, asked, 0.1, kernel="cpp")
    assert dictionary.dtype == torch.float16 and torch.isfinite(dictionary).all()


def test_the_kernel_choice_follows_the_argument_and_the_environment(monkeypatch) -> None:
    from parallax.coding import native

    monkeypatch.setenv(native.KERNEL_ENV, "torch")
    assert native.kernels_for(None, torch.zeros(1)) is None
    monkeypatch.setenv(native.KERNEL_ENV, "fortran")
    with pytest.raises(ValueError, match="PARALLAX_PURSUIT_KERNEL"):
        matching_pursuit(torch.zeros(2, K), random_dictionary(N, K, torch.Generator()), SPARSITY)
    with pytest.raises(ValueError, match="kernel"):
        matching_pursuit(
            torch.zeros(2, K),
            random_dictionary(N, K, torch.Generator()),
            SPARSITY,
            kernel="fortran",
        )


def test_kernels_that_differ_by_one_bit_are_refused_at_load_time(compiled, monkeypatch) -> None:
    # the package hands the loader its check (parallax.coding.native_check), which compares
    # every kernel with the numpy/torch code before the coder may use one
    from types import SimpleNamespace

    from parallax.coding import native, native_check

    assert native._self_check is native_check.self_check

    def gram_pursuit(correlations, gram, sparsity):
        picks, coefficients = compiled.gram_pursuit(correlations, gram, sparsity)
        return picks, torch.nextafter(coefficients, torch.full_like(coefficients, np.inf))

    names = ("codes_and_residuals", "residuals_only", "codes_times_residuals", "dictionary_step")
    names += ("encode_pairs", "pooled_activity", "encode_scales", "start_dictionary_steps")
    off = SimpleNamespace(gram_pursuit=gram_pursuit, **{n: getattr(compiled, n) for n in names})
    monkeypatch.setattr(native, "_build", lambda: off)
    monkeypatch.setattr(native, "_loaded", False)
    monkeypatch.setattr(native, "_module", None)
    monkeypatch.setattr(native, "_failure", None)
    assert native.load_kernels() is None
    assert "coefficients differ" in native.kernel_failure()


def test_without_the_kernels_the_coder_falls_back_with_one_warning(monkeypatch, caplog) -> None:
    from parallax.coding import native
    from parallax.coding.dictionary import gradient_step_

    def no_compiler():
        raise RuntimeError("no C++ compiler (simulated)")

    monkeypatch.setattr(native, "_build", no_compiler)
    monkeypatch.setattr(native, "_loaded", False)
    monkeypatch.setattr(native, "_module", None)
    monkeypatch.setattr(native, "_failure", None)
    monkeypatch.delenv(native.KERNEL_ENV, raising=False)
    dictionary = random_dictionary(N, K, torch.Generator().manual_seed(26))
    patches = _unit_rows(50, K, seed=27, dtype=torch.float32)
    with caplog.at_level("WARNING", logger=native.__name__):
        fallback = matching_pursuit(patches, dictionary, SPARSITY)
        again = matching_pursuit(patches, dictionary, SPARSITY)
        gradient_step_(dictionary.clone(), fallback, 0.2)
    warnings = [record for record in caplog.records if record.name == native.__name__]
    assert len(warnings) == 1 and "simulated" in warnings[0].getMessage()
    assert native.kernels_for("auto", torch.zeros(1)) is None
    reference = matching_pursuit(patches, dictionary, SPARSITY, kernel="torch")
    assert torch.equal(fallback.atom_indices, reference.atom_indices)
    assert torch.equal(again.codes, reference.codes)
    with pytest.raises(RuntimeError, match="simulated"):
        matching_pursuit(patches, dictionary, SPARSITY, kernel="cpp")
