"""The sparse coder's inner loops in numpy/torch (paper §3.3, eq. 1 and the dictionary step).

These are the definitions the compiled CPU kernels of ``pursuit_kernel.cpp`` must reproduce bit
for bit (:mod:`parallax.coding.native_check` checks them against these functions before the
coder uses them), and the code that runs wherever the kernels do not: without a C++ compiler,
on other devices, in other dtypes. Each function works on plain tensors and mirrors one kernel:

* :func:`gram_steps_cpu` (and :func:`gram_steps` for any device) — ``gram_pursuit``, the k
  Gram-form matching-pursuit steps: picks and coefficients;
* :func:`codes_and_residuals` — ``codes_and_residuals``, the dense codes and the residuals from
  the picks (``residuals_only`` gives its second half);
* :func:`codes_times_residuals` — ``codes_times_residuals``, the dictionary gradient's Bᵀ·R.

Dictionaries are (N, K) with atoms as rows; patches are (M, K) rows. The module imports no other
part of the coder, so that the pursuit, the dictionary and the kernels' loader can all use it.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F


def dense_codes(
    atom_indices: torch.Tensor, coefficients: torch.Tensor, n_atoms: int
) -> torch.Tensor:
    """(M, N) coefficients b_{i,n} from the per-step picks; repeated picks accumulate."""
    codes = coefficients.new_zeros(coefficients.shape[0], n_atoms)
    return codes.scatter_add_(1, atom_indices, coefficients)


def reconstruct(
    dictionary: torch.Tensor, atom_indices: torch.Tensor, coefficients: torch.Tensor
) -> torch.Tensor:
    """Σ_s c_s·φ_{k_s} per patch, (M, K), from the picks alone: M·k·K work instead of M·N·K."""
    return F.embedding_bag(atom_indices, dictionary, per_sample_weights=coefficients, mode="sum")


def codes_and_residuals(
    patches: torch.Tensor,
    dictionary: torch.Tensor,
    atom_indices: torch.Tensor,
    coefficients: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The (M, N) dense codes and the (M, K) residuals γ − Σ_s c_s·φ_{k_s} of a pursuit's picks."""
    codes = dense_codes(atom_indices, coefficients, dictionary.shape[0])
    return codes, patches - reconstruct(dictionary, atom_indices, coefficients)


def gram_steps(
    correlations: torch.Tensor, gram: torch.Tensor, sparsity: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """The pursuit steps in torch, for any device: (M, sparsity) picks and coefficients.

    ``correlations`` (M, N) = patches·Φᵀ are updated in place; ``gram`` is Φ·Φᵀ."""
    # One M×N buffer reused by every step: fresh allocations cost as much as the arithmetic here.
    gram_rows = torch.empty_like(correlations)
    picks, coefficients = [], []
    for _ in range(sparsity):
        picked = correlations.abs().argmax(dim=1)
        coefficient = correlations.gather(1, picked.unsqueeze(1))
        picks.append(picked)
        coefficients.append(coefficient.squeeze(1))
        # The residual r − c·φ_k has correlations C − c·G[k]: no pass over K needed.
        torch.index_select(gram, 0, picked, out=gram_rows)
        correlations.addcmul_(coefficient, gram_rows, value=-1.0)
    return torch.stack(picks, dim=1), torch.stack(coefficients, dim=1)


def gram_steps_cpu(
    correlations: torch.Tensor, gram: torch.Tensor, sparsity: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`gram_steps` on the CPU, with the row-wise |argmax| and the pick bookkeeping in
    numpy on zero-copy views: numpy's row argmax is much quicker than torch's on the CPU, and a
    small torch call's dispatch costs more than the arithmetic of one step."""
    values = correlations.numpy()
    magnitudes = np.empty_like(values)
    gram_rows = torch.empty_like(correlations)
    every_row = np.arange(values.shape[0])
    picks, coefficients = [], []
    for _ in range(sparsity):
        np.abs(values, out=magnitudes)
        picked = magnitudes.argmax(axis=1)  # first maximum on ties, like torch
        coefficient = values[every_row, picked]
        picks.append(picked)
        coefficients.append(coefficient)
        torch.index_select(gram, 0, torch.from_numpy(picked), out=gram_rows)
        correlations.addcmul_(torch.from_numpy(coefficient).unsqueeze(1), gram_rows, value=-1.0)
    return torch.from_numpy(np.stack(picks, axis=1)), torch.from_numpy(
        np.stack(coefficients, axis=1)
    )


def codes_times_residuals(
    atom_indices: torch.Tensor, coefficients: torch.Tensor, residuals: torch.Tensor, n_atoms: int
) -> torch.Tensor:
    """Bᵀ·R, (N, K): for every atom, the coefficient-weighted sum of the residuals of the patches
    that picked it, in (patch, step) order. Grouping the M·k picks by atom costs M·k·K instead
    of the dense N·M·K."""
    picks = atom_indices.reshape(-1)
    order = stable_order(picks, n_atoms)
    counts = torch.bincount(picks, minlength=n_atoms)
    offsets = torch.zeros_like(counts)
    offsets[1:] = torch.cumsum(counts, 0)[:-1]
    patch_of_pick = torch.div(order, atom_indices.shape[1], rounding_mode="floor")
    return F.embedding_bag(
        patch_of_pick,
        residuals,
        offsets=offsets,
        mode="sum",
        per_sample_weights=coefficients.reshape(-1)[order],
    )


def stable_order(picks: torch.Tensor, n_atoms: int) -> torch.Tensor:
    """Stable argsort of atom indices; on the CPU numpy's radix sort of int16 keys, which is
    quicker than a comparison sort."""
    if picks.device.type == "cpu" and n_atoms <= np.iinfo(np.int16).max:
        keys = picks.numpy().astype(np.int16)
        return torch.from_numpy(np.argsort(keys, kind="stable"))
    return torch.argsort(picks, stable=True)
