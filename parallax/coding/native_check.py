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
from .retina import NEAR_CONSTANT_TOLERANCE, extract_patches, prepare_reference, stack_pair


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
                *_helper_thread_pairs(module, atoms, dtype, generator),
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


def _helper_thread_pairs(module, atoms: int, dtype: torch.dtype, generator) -> list:
    """(name, the kernel's, the separate calls') for two scales encoded in one call (the second
    on the kernels' helper thread) and their dictionary steps handed to that thread."""
    dictionaries = [torch.randn(atoms, 8, generator=generator, dtype=dtype) for _ in range(2)]
    for dictionary in dictionaries:
        dictionary /= dictionary.norm(dim=1, keepdim=True)
    grams = [dictionary @ dictionary.T for dictionary in dictionaries]
    images = [torch.rand(2, 5, 5, generator=generator, dtype=dtype) for _ in range(2)]
    strides = [1, 3]
    raws = [extract_patches(image, 2, stride) for image, stride in zip(images, strides)]
    references = [prepare_reference(torch.rand_like(raw), "per_half") for raw in raws]
    expected = [
        module.encode_pairs(reference, raw, dictionary, gram, 3, True, NEAR_CONSTANT_TOLERANCE)
        for reference, raw, dictionary, gram in zip(references, raws, dictionaries, grams)
    ]
    state, reward, encoded = module.encode_scales(
        references, images, [2, 2], strides, dictionaries, grams, 3, True, NEAR_CONSTANT_TOLERANCE
    )
    checked = [
        ("one-call state", state, torch.cat([scale[3] for scale in expected], dim=1)),
        ("one-call reward", reward, -torch.stack([scale[4] for scale in expected]).sum(dim=0)),
    ]
    for s, (got, theirs) in enumerate(zip(encoded, expected)):
        checked += [(f"scale {s}'s one-call encoding", a, b) for a, b in zip(got, theirs)]
        checked.append((f"scale {s}'s raw patches", got[5], raws[s]))
    stepped = [dictionary.clone() for dictionary in dictionaries]
    gram_steps = module.start_dictionary_steps(
        stepped,
        [[scale[0]] for scale in expected],
        [[scale[1]] for scale in expected],
        [[scale[2]] for scale in expected],
        [0.1, 0.2],
        MIN_ATOM_NORM,
    ).wait()
    for s, (scale, alpha) in enumerate(zip(expected, (0.1, 0.2))):
        alone = dictionaries[s].clone()
        gram = module.dictionary_step(
            alone, [scale[0]], [scale[1]], [scale[2]], alpha, MIN_ATOM_NORM
        )
        checked += [
            (f"scale {s}'s dictionary step on the helper", stepped[s], alone),
            (f"scale {s}'s Gram matrix from the helper", gram_steps[s], gram),
        ]
    return checked
