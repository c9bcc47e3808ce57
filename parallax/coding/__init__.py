"""Sensory coding model (paper §3.3, eqs. 1–6, Fig. 5): retina, matching pursuit, dictionaries.

``MultiScaleCoder`` is what the trainer instantiates from ``conf/coder/``; the other names are
its parts, exported for tests, notebooks and the benchmark (``parallax.tools.bench.coding``).
"""

from . import native, native_check
from .atoms import atom_grid, save_png
from .coder import CoderOutput, DictionarySteps, Encoding, MultiScaleCoder, scale_seed
from .dictionary import gradient_step_, pooled_activity, random_dictionary, reconstruction_error
from .pursuit import SparseCode, gram_matrix, matching_pursuit, matching_pursuit_recompute
from .retina import ScaleSpec, as_gray_batch, scale_patches, stack_pair, zero_mean_unit_norm
from .scale import ScaleCoder, ScaleOutput

# The compiled kernels are checked against the dictionary and pursuit code, which use them: the
# check is handed to the loader here, above both, before anything can load the kernels.
native.set_self_check(native_check.self_check)

__all__ = [
    "CoderOutput",
    "DictionarySteps",
    "Encoding",
    "MultiScaleCoder",
    "ScaleCoder",
    "ScaleOutput",
    "ScaleSpec",
    "SparseCode",
    "as_gray_batch",
    "atom_grid",
    "gradient_step_",
    "gram_matrix",
    "matching_pursuit",
    "matching_pursuit_recompute",
    "pooled_activity",
    "random_dictionary",
    "reconstruction_error",
    "save_png",
    "scale_patches",
    "scale_seed",
    "stack_pair",
    "zero_mean_unit_norm",
]
