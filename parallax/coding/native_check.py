"""The load-time check of the sparse coder's compiled kernels (paper §3.3, eq. 1).

:func:`self_check` runs every function of ``pursuit_kernel.cpp`` on random data, in float32 and
float64, against the numpy/torch code the coder would use without them
(:mod:`parallax.coding.reference`, the torch dictionary step and Gram matrix, the retina's pair
normalisations and the reconstruction error), and raises at the first result that differs in a
single bit. :func:`parallax.coding.native.load_kernels` runs it on the module it has just built;
the package registers it there (``native.set_self_check``), since the code it compares with
uses :mod:`parallax.coding.native` itself.
"""

from __future__ import annotations

from types import ModuleType

import torch

from . import reference
from .dictionary import MIN_ATOM_NORM, gradient_step_, reconstruction_error
from .pursuit import SparseCode, gram_matrix
from .retina import NEAR_CONSTANT_TOLERANCE, prepare_reference, stack_pair


def self_check(module: ModuleType) -> None:
    """The kernels must give the numpy/torch code's results exactly, in both dtypes."""
    generator = torch.Generator().manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        for atoms in (40, 37, 75):  # whole vector lanes only, and a tail after them (short, long)
            dictionary = torch.randn(atoms, 12, generator=generator, dtype=dtype)
            dictionary /= dictionary.norm(dim=1, keepdim=True)
            patches = torch.randn(64, 12, generator=generator, dtype=dtype)
            correlations = patches @ dictionary.T
            gram = dictionary @ dictionary.T
            picks, coefficients = reference.gram_steps_cpu(correlations.clone(), gram, 8)
            codes, residuals = reference.codes_and_residuals(
                patches, dictionary, picks, coefficients
            )
            got_picks, got_coefficients = module.gram_pursuit(correlations.clone(), gram, 8)
            got_codes, got_residuals = module.codes_and_residuals(
                patches, dictionary, picks, coefficients
            )
            for name, mine, theirs in (
                ("picks", got_picks, picks),
                ("coefficients", got_coefficients, coefficients),
                ("codes", got_codes, codes),
                ("residuals", got_residuals, residuals),
                (
                    "residuals alone",
                    module.residuals_only(patches, dictionary, picks, coefficients),
                    residuals,
                ),
                (
                    "B^T R",
                    module.codes_times_residuals(picks, coefficients, residuals, atoms),
                    reference.codes_times_residuals(picks, coefficients, residuals, atoms),
                ),
                *_dictionary_step_pairs(module, dictionary, picks, coefficients, codes, residuals),
                *_encode_pairs_pairs(module, dictionary, gram, generator),
            ):
                if not torch.equal(mine, theirs):
                    raise RuntimeError(
                        f"its {dtype} {name} differ from the numpy/torch code's on this machine"
                    )


def _dictionary_step_pairs(module, dictionary, picks, coefficients, codes, residuals) -> list:
    """(name, the kernel's, the numpy/torch code's) for the one-call dictionary step and its
    Gram matrix."""
    expected, stepped = dictionary.clone(), dictionary.clone()
    gradient_step_(expected, SparseCode(picks, coefficients, codes, residuals), 0.1, "torch")
    gram = module.dictionary_step(
        stepped, [picks], [coefficients], [residuals], 0.1 / residuals.shape[0], MIN_ATOM_NORM
    )
    return [("dictionary step", stepped, expected), ("Gram matrix", gram, gram_matrix(expected))]


def _encode_pairs_pairs(module, dictionary, gram, generator) -> list:
    """(name, the kernel's, the numpy/torch code's) for the one-call encoding of a scale, in both
    normalisations (θ from the picks is compared with the θ kernel, which the coder checks per
    shape against torch)."""
    half = dictionary.shape[1] // 2
    raw_reference, raw = torch.randn(2, 2, 9, half, generator=generator, dtype=dictionary.dtype)
    pairs_checked = []
    for normalisation in ("per_half", "joint"):
        cached = prepare_reference(raw_reference, normalisation)
        pairs = stack_pair(cached, raw, normalisation)
        flat = pairs.reshape(18, 2 * half)
        picks, coefficients = reference.gram_steps_cpu(flat @ dictionary.T, gram, 5)
        _, residuals = reference.codes_and_residuals(flat, dictionary, picks, coefficients)
        expected = (
            picks,
            coefficients,
            residuals,
            module.pooled_activity(picks, coefficients, 9, dictionary.shape[0]),
            reconstruction_error(pairs, residuals.reshape(2, 9, 2 * half)),
        )
        got = module.encode_pairs(
            cached, raw, dictionary, gram, 5, normalisation == "per_half", NEAR_CONSTANT_TOLERANCE
        )
        names = ("picks", "coefficients", "residuals", "theta", "e")
        pairs_checked += [
            (f"one-call encoding's {name} ({normalisation})", mine, theirs)
            for name, mine, theirs in zip(names, got, expected)
        ]
    return pairs_checked
