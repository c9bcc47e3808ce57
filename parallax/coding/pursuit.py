"""Matching pursuit, the sparse encoder of the sensory coding model (paper §3.3, eq. 1).

Plain matching pursuit (Mallat & Zhang), not orthogonal MP: at each of ``sparsity`` steps every
patch picks the atom with the largest |correlation| with its residual, adds that correlation to
the atom's coefficient (an atom may be picked again; coefficients accumulate) and subtracts the
atom from the residual.

:func:`matching_pursuit` is batched over all patches at once in Gram-matrix form: correlations
C = X·Φᵀ are computed once, then each step updates them as C ← C − c·G[k] with G = Φ·Φᵀ, which
costs P·N per step instead of P·K·N. :func:`matching_pursuit_recompute` is the straightforward
version that recomputes all correlations from the residual at every step; it is kept for tests
and for the benchmark that compares the two. Residuals are rebuilt from the k picks per patch
(``embedding_bag``), not from the dense (M, N) codes.

On the CPU the k Gram-form steps, the dense codes and the residuals run in compiled kernels
(``pursuit_kernel.cpp``, built on first use by :mod:`parallax.coding.native`) that pursue patch
by patch with the patch's correlations in L1 cache; their results are bit-identical to those of
the numpy/torch code of :mod:`parallax.coding.reference`, which remains the fallback when no
compiler is available and runs on other devices. The choice is ``kernel=`` of
:func:`matching_pursuit` or the environment variable ``PARALLAX_PURSUIT_KERNEL``: ``auto``
(default), ``cpp`` or ``torch``.

Dictionaries are (N, K) with atoms as unit-norm rows; patches are (M, K) rows. Any float dtype
and device work; on the CPU the per-step bookkeeping runs in numpy on zero-copy views.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from . import native, reference


@dataclass
class SparseCode:
    """The outcome of one pursuit over M patches with ``sparsity`` steps."""

    atom_indices: torch.Tensor  # (M, sparsity) int64: atom picked at each step
    coefficients: torch.Tensor  # (M, sparsity): correlation added at each step
    # (M, N): b_{i,n}, repeated picks of one atom summed; None when the pursuit was asked not to
    # make them (the compiled kernels compute θ from the picks, see dictionary.pooled_activity_of)
    codes: torch.Tensor | None
    residuals: torch.Tensor  # (M, K): γ − Σ_n b_n·φ_n after the last step


def gram_matrix(dictionary: torch.Tensor) -> torch.Tensor:
    """G = Φ·Φᵀ, (N, N), for the Gram-form pursuit."""
    return dictionary @ dictionary.T


def _check_inputs(patches: torch.Tensor, dictionary: torch.Tensor) -> None:
    if patches.dim() != 2 or dictionary.dim() != 2 or patches.shape[1] != dictionary.shape[1]:
        raise ValueError(
            f"patches (M,K) and dictionary (N,K) disagree: {tuple(patches.shape)} "
            f"vs {tuple(dictionary.shape)}"
        )
    if patches.dtype != dictionary.dtype or patches.device != dictionary.device:
        raise ValueError(
            f"patches ({patches.dtype}, {patches.device}) and dictionary "
            f"({dictionary.dtype}, {dictionary.device}) must share dtype and device"
        )


def _code(
    patches: torch.Tensor,
    dictionary: torch.Tensor,
    atom_indices: torch.Tensor,
    coefficients: torch.Tensor,
) -> SparseCode:
    codes, residuals = reference.codes_and_residuals(
        patches, dictionary, atom_indices, coefficients
    )
    return SparseCode(atom_indices, coefficients, codes, residuals)


@torch.no_grad()
def matching_pursuit(
    patches: torch.Tensor,
    dictionary: torch.Tensor,
    sparsity: int,
    gram: torch.Tensor | None = None,
    kernel: str | None = None,
    dense_codes: bool = True,
) -> SparseCode:
    """Batched plain MP in Gram form. ``gram`` may be passed when it is cached (Φ unchanged).

    With ``dense_codes=False`` the compiled kernels skip the (M, N) codes (``codes`` is None):
    the coder's θ comes from the picks instead, and the codes are most of the memory traffic.

    ``kernel`` picks the CPU implementation: ``"auto"`` (the compiled kernels when they can be
    built, else numpy/torch), ``"cpp"`` (the kernels, or an error) or ``"torch"``; None reads
    ``PARALLAX_PURSUIT_KERNEL`` (default ``auto``). All give the same result, bit for bit; other
    devices and dtypes than float32/float64 always use torch.
    """
    _check_inputs(patches, dictionary)
    if gram is None:
        gram = gram_matrix(dictionary)
    correlations = patches @ dictionary.T  # (M, N), updated in place
    compiled = native.kernels_for(kernel, correlations)
    if compiled is not None:
        atom_indices, coefficients = compiled.gram_pursuit(
            correlations, gram.contiguous(), sparsity
        )
        if not dense_codes:
            residuals = compiled.residuals_only(
                patches.contiguous(), dictionary.contiguous(), atom_indices, coefficients
            )
            return SparseCode(atom_indices, coefficients, None, residuals)
        codes, residuals = compiled.codes_and_residuals(
            patches.contiguous(), dictionary.contiguous(), atom_indices, coefficients
        )
        return SparseCode(atom_indices, coefficients, codes, residuals)
    cpu = correlations.device.type == "cpu"
    steps = reference.gram_steps_cpu if cpu else reference.gram_steps
    atom_indices, coefficients = steps(correlations, gram, sparsity)
    return _code(patches, dictionary, atom_indices, coefficients)


def _abs_argmax(values: torch.Tensor) -> torch.Tensor:
    """Row-wise index of the largest |value| (first on ties); numpy's argmax on the CPU (faster)."""
    if values.device.type == "cpu":
        return torch.from_numpy(np.abs(values.numpy()).argmax(axis=1))
    return values.abs().argmax(dim=1)


@torch.no_grad()
def matching_pursuit_recompute(
    patches: torch.Tensor, dictionary: torch.Tensor, sparsity: int
) -> SparseCode:
    """The straightforward batched MP: correlations recomputed from the residual at every step."""
    _check_inputs(patches, dictionary)
    residuals = patches.clone()
    rows = patches.shape[0]
    atom_indices = torch.empty(rows, sparsity, dtype=torch.long, device=patches.device)
    coefficients = torch.empty(rows, sparsity, dtype=patches.dtype, device=patches.device)
    for step in range(sparsity):
        correlations = residuals @ dictionary.T
        picked = _abs_argmax(correlations)
        coefficient = correlations.gather(1, picked.unsqueeze(1))
        atom_indices[:, step] = picked
        coefficients[:, step : step + 1] = coefficient
        residuals -= coefficient * dictionary.index_select(0, picked)
    codes = reference.dense_codes(atom_indices, coefficients, dictionary.shape[0])
    return SparseCode(atom_indices, coefficients, codes, residuals)
