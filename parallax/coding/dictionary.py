"""Dictionary learning and the per-scale outputs of the sensory coding model (paper §3.3).

* the dictionary φ^j: N = 288 unit-norm atoms of K = 200, randomly initialised (§3.3), stored
  as the ROWS of an (N, K) tensor;
* one gradient step on the reconstruction error after each encoding, then renormalisation of
  every atom (§3.3, last paragraph): ΔΦ = η·R·Bᵀ/P with atoms as columns, i.e.
  Φ ← Φ + (η/P)·Bᵀ·R with atoms as rows, R the (P, K) residuals, B the (P, N) codes; for B
  robots in lockstep either the mean of their steps or (beyond the paper) their sum;
* pooled activity θ_n = mean_i b_{i,n}² (eqs. 2–3) and reconstruction error
  e = mean_i ‖γ_i − Φᵀb_i‖² / ‖γ_i‖² (eq. 4), where a zero patch (a flat region, see
  ``retina``) contributes 0: its 0/0 is defined as 0.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from . import native, reference
from .pursuit import SparseCode

#: Atoms are divided by max(‖φ‖, this); a gradient step never comes close to zeroing an atom.
MIN_ATOM_NORM = 1e-12


def random_dictionary(
    n_atoms: int, dim: int, generator: torch.Generator, dtype: torch.dtype = torch.float32
) -> torch.Tensor:
    """(n_atoms, dim) Gaussian atoms normalised to unit length; reproducible from ``generator``."""
    atoms = torch.randn(n_atoms, dim, generator=generator, dtype=torch.float64)
    return normalise_atoms_(atoms).to(dtype)


def normalise_atoms_(dictionary: torch.Tensor) -> torch.Tensor:
    """Scale every row to unit norm, in place."""
    norms = torch.linalg.vector_norm(dictionary, dim=1, keepdim=True).clamp_min_(MIN_ATOM_NORM)
    return dictionary.div_(norms)


def codes_times_residuals(
    code: SparseCode | Sequence[SparseCode], n_atoms: int, kernel: str | None = None
) -> torch.Tensor:
    """Bᵀ·R, (N, K): for every atom, the coefficient-weighted sum of the residuals of the patches
    that picked it. Grouping the M·k picks by atom costs M·k·K instead of the dense N·M·K.

    ``code`` may be a list of codes of consecutive chunks of patches (the robots of a lockstep,
    encoded one after another): the result is that of their concatenation, bit for bit.

    On the CPU a compiled kernel adds up the same terms in the same order, chunk after chunk into
    one product (``kernel``: see :mod:`parallax.coding.native`); elsewhere, or without it,
    :func:`parallax.coding.reference.codes_times_residuals` does, on the concatenated chunks."""
    chunks = [code] if isinstance(code, SparseCode) else list(code)
    compiled = native.kernels_for(kernel, chunks[0].residuals)
    if compiled is not None:
        product = None
        for chunk in chunks:
            product = compiled.codes_times_residuals(
                chunk.atom_indices.contiguous(),
                chunk.coefficients.contiguous(),
                chunk.residuals.contiguous(),
                n_atoms,
                product,
            )
        return product
    return reference.codes_times_residuals(
        torch.cat([chunk.atom_indices for chunk in chunks]),
        torch.cat([chunk.coefficients for chunk in chunks]),
        torch.cat([chunk.residuals for chunk in chunks]),
        n_atoms,
    )


@torch.no_grad()
def gradient_step_(
    dictionary: torch.Tensor,
    code: SparseCode | Sequence[SparseCode],
    learning_rate: float,
    kernel: str | None = None,
    images: int = 1,
) -> None:
    """One step of gradient descent on ½‖γ − Φᵀb‖² averaged over the P coded patches, in place
    (``code``: one code, or the codes of consecutive chunks of the patches).

    ``images`` > 1 takes the sum of that many images' steps instead of their mean: the patches
    come from that many images of equal size, and each image's step is η·Bᵀ·R/P of its own P
    patches (B robots' experience counts B times; the atoms are renormalised once, after the
    sum)."""
    chunks, step = chunks_and_step(code, learning_rate, images)
    if step is None:
        return
    dictionary.add_(codes_times_residuals(chunks, dictionary.shape[0], kernel), alpha=step)
    normalise_atoms_(dictionary)


def chunks_and_step(
    code: SparseCode | Sequence[SparseCode], learning_rate: float, images: int
) -> tuple[list[SparseCode], float | None]:
    """The code as its list of chunks, and the step size η·images/P over their P patches
    (None when there are none)."""
    chunks = [code] if isinstance(code, SparseCode) else list(code)
    patches = sum(chunk.residuals.shape[0] for chunk in chunks)
    return chunks, (learning_rate * images / patches if patches else None)


def gradient_step_and_gram_(
    dictionary: torch.Tensor,
    code: SparseCode | Sequence[SparseCode],
    learning_rate: float,
    kernel: str | None = None,
    images: int = 1,
) -> torch.Tensor | None:
    """:func:`gradient_step_`, then the Gram matrix Φ·Φᵀ of the new dictionary, returned, in one
    call of the compiled kernels, the same numbers: the GIL stays released throughout, so a
    thread that runs meanwhile (the policy's, in a lockstep) never waits for it. None, with
    nothing done, where the kernels do not apply (another device, ``kernel`` "torch", no
    patches)."""
    chunks, step = chunks_and_step(code, learning_rate, images)
    compiled = native.kernels_for(kernel, dictionary)
    if compiled is None or step is None or not dictionary.is_contiguous():
        return None
    return compiled.dictionary_step(
        dictionary,
        [chunk.atom_indices for chunk in chunks],
        [chunk.coefficients for chunk in chunks],
        [chunk.residuals for chunk in chunks],
        step,
        MIN_ATOM_NORM,
    )


def pooled_activity(codes: torch.Tensor) -> torch.Tensor:
    """θ (eqs. 2–3): (B, P, N) codes → (B, N) mean squared coefficient of every atom."""
    return codes.square().mean(dim=1)


_EXACT_POOLED_ACTIVITY: dict[tuple, bool] = {}


def exact_pooled_activity_kernel(
    patches: int, n_atoms: int, sparsity: int, dtype: torch.dtype, kernel: str | None = None
) -> bool:
    """Whether the compiled θ kernel (chosen by ``kernel``, see :mod:`parallax.coding.native`)
    gives :func:`pooled_activity`'s θ bit for bit for images of ``patches`` patches and
    ``n_atoms`` atoms. It replays torch's summation order, which depends on the shape (torch
    sums the last columns that do not fill its widest vectors in another order) and on its
    thread count, so each case is checked once, on random picks with repeats, against torch."""
    compiled = native.kernels_for(kernel, torch.empty(0, dtype=dtype))
    if compiled is None:
        return False
    # torch's θ depends on its thread count too (a reduction may be split between threads)
    key = (patches, n_atoms, sparsity, dtype, torch.get_num_threads())
    if key not in _EXACT_POOLED_ACTIVITY:
        generator = torch.Generator().manual_seed(patches * 1_000_003 + n_atoms)
        picks = torch.randint(0, n_atoms, (2 * patches, sparsity), generator=generator)
        coefficients = torch.randn(2 * patches, sparsity, generator=generator, dtype=dtype)
        dense = reference.dense_codes(picks, coefficients, n_atoms).reshape(2, patches, n_atoms)
        _EXACT_POOLED_ACTIVITY[key] = torch.equal(
            compiled.pooled_activity(picks, coefficients, patches, n_atoms), pooled_activity(dense)
        )
    return _EXACT_POOLED_ACTIVITY[key]


def pooled_activity_of(code: SparseCode, images: int, n_atoms: int) -> torch.Tensor:
    """θ (B, N) of a code of ``images`` images: from its dense codes, or — when the pursuit did
    not make them, which the coder only asks for where :func:`exact_pooled_activity_kernel`
    holds — from its picks in the compiled kernel."""
    if code.codes is not None:
        return pooled_activity(code.codes.reshape(images, -1, n_atoms))
    compiled = native.kernels_for("cpp", code.coefficients)
    return compiled.pooled_activity(
        code.atom_indices, code.coefficients, code.atom_indices.shape[0] // images, n_atoms
    )


def reconstruction_error(patches: torch.Tensor, residuals: torch.Tensor) -> torch.Tensor:
    """e (eq. 4): (B, P, K) patches and residuals → (B,); a zero patch's 0/0 counts as 0."""
    patch_energy = patches.square().sum(dim=-1)
    residual_energy = residuals.square().sum(dim=-1)
    has_energy = patch_energy > 0
    ratio = residual_energy / torch.where(has_energy, patch_energy, torch.ones_like(patch_energy))
    return torch.where(has_energy, ratio, torch.zeros_like(ratio)).mean(dim=1)
