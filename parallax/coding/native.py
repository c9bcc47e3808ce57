"""The compiled CPU kernels of the sparse coder (``pursuit_kernel.cpp``, paper §3.3, eq. 1).

Seven functions: ``gram_pursuit`` (the k Gram-form matching-pursuit steps, patch by patch),
``codes_and_residuals`` (dense codes and residuals from the picks), ``residuals_only``,
``pooled_activity`` (θ from the picks, summed in torch's order, without the dense codes; checked
per shape by :func:`parallax.coding.dictionary.exact_pooled_activity_kernel`),
``codes_times_residuals`` (the dictionary gradient's Bᵀ·R), ``dictionary_step`` (the whole
dictionary step and the next Gram matrix in one call, which keeps the GIL released throughout)
and ``encode_pairs`` (one scale's whole encoding in one call, likewise).
:func:`load_kernels` builds the C++ file on first use with ``torch.utils.cpp_extension.load``
(-O3; needs a C++ compiler and the ``ninja`` package; torch caches the build under
``~/.cache/torch_extensions`` or ``$TORCH_EXTENSIONS_DIR``, so later processes only load it),
then checks once that all of them reproduce the numpy/torch code of
:mod:`parallax.coding.reference` bit for bit on random data.
It returns the module, or ``None`` — with one warning line saying why — when the kernels cannot
be built or disagree.

Which implementation the coder uses on the CPU is chosen by the ``kernel`` argument of
:func:`parallax.coding.pursuit.matching_pursuit` and
:func:`parallax.coding.dictionary.gradient_step_`, or else by the environment variable
``PARALLAX_PURSUIT_KERNEL``: ``auto`` (the default: the kernels when they are available, else
the numpy/torch code), ``cpp`` (the kernels or an error) or ``torch`` (always numpy/torch).
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import torch

from . import reference

log = logging.getLogger(__name__)

KERNEL_ENV = "PARALLAX_PURSUIT_KERNEL"
KERNEL_CHOICES = ("auto", "cpp", "torch")
SOURCE = Path(__file__).with_name("pursuit_kernel.cpp")

#: torch's CPU kernels that round ``a + s·b·c`` as one fused multiply-add (checked at load time).
_FMA_CAPABILITIES = ("AVX2", "AVX512")

# The coder's helper thread may ask for the kernels while this thread builds them: it must wait
# for the build rather than take the unfinished state for a failed one.
_load_lock = threading.Lock()
_loaded = False
_module: ModuleType | None = None
_failure: str | None = None


def kernel_choice() -> str:
    """The value of ``PARALLAX_PURSUIT_KERNEL`` (default ``auto``), validated."""
    choice = os.environ.get(KERNEL_ENV, "auto").strip().lower() or "auto"
    if choice not in KERNEL_CHOICES:
        raise ValueError(f"{KERNEL_ENV} must be one of {KERNEL_CHOICES}, got {choice!r}")
    return choice


def _build() -> ModuleType:
    from torch.utils import cpp_extension

    if not cpp_extension.is_ninja_available():
        raise RuntimeError("the ninja package is not installed (pip install ninja)")
    capability = torch.backends.cpu.get_cpu_capability()
    flags = ["-O3", "-ffp-contract=off"]
    if capability in _FMA_CAPABILITIES:
        # torch runs its AVX2 kernels on this CPU, so it has AVX2 and FMA too.
        flags += ["-mavx2", "-mfma", "-DPARALLAX_FMA"]
    if capability == "AVX512":
        # 32 vector registers and mask registers for the pursuit's 32-byte vectors (torch runs
        # its AVX512 kernels only where AVX512F, VL, BW and DQ are all present).
        flags += ["-mavx512f", "-mavx512vl", "-mavx512bw", "-mavx512dq"]
    name = f"parallax_pursuit_{capability.lower()}"
    build_directory = _build_directory(cpp_extension, name)
    if not (build_directory / f"{name}.so").exists():
        log.info("compiling the matching-pursuit kernels into %s (once)", build_directory)
    with _exclusive(build_directory / "parallax.flock"):
        # torch's own lock file outlives a build that was killed, and then every later build
        # waits for it forever; while we hold our lock no other build of ours can be running.
        (build_directory / "lock").unlink(missing_ok=True)
        return cpp_extension.load(
            name=name,
            sources=[str(SOURCE)],
            extra_cflags=flags,
            build_directory=str(build_directory),
            verbose=False,
        )


def _build_directory(cpp_extension: ModuleType, name: str) -> Path:
    """Where torch would build ``name`` (``$TORCH_EXTENSIONS_DIR`` or its cache), created."""
    torchs_choice = getattr(cpp_extension, "_get_build_directory", None)
    if torchs_choice is not None:
        return Path(torchs_choice(name, verbose=False))
    root = os.environ.get("TORCH_EXTENSIONS_DIR") or cpp_extension.get_default_build_root()
    directory = Path(root) / name
    directory.mkdir(parents=True, exist_ok=True)
    return directory


@contextlib.contextmanager
def _exclusive(path: Path) -> Iterator[None]:
    """An advisory lock on ``path`` that the system drops when its process dies (POSIX only)."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _self_check(module: ModuleType) -> None:
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
    from .dictionary import _MIN_ATOM_NORM, gradient_step_
    from .pursuit import SparseCode, gram_matrix

    expected, stepped = dictionary.clone(), dictionary.clone()
    gradient_step_(expected, SparseCode(picks, coefficients, codes, residuals), 0.1, "torch")
    gram = module.dictionary_step(
        stepped, [picks], [coefficients], [residuals], 0.1 / residuals.shape[0], _MIN_ATOM_NORM
    )
    return [("dictionary step", stepped, expected), ("Gram matrix", gram, gram_matrix(expected))]


def _encode_pairs_pairs(module, dictionary, gram, generator) -> list:
    """(name, the kernel's, the numpy/torch code's) for the one-call encoding of a scale, in both
    normalisations (θ from the picks is compared with the θ kernel, which the coder checks per
    shape against torch)."""
    from .dictionary import reconstruction_error
    from .retina import NEAR_CONSTANT_TOLERANCE, prepare_reference, stack_pair

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


def load_kernels() -> ModuleType | None:
    """The compiled module, built and checked on the first call; None if unavailable."""
    global _loaded, _module, _failure
    if _loaded:
        return _module
    with _load_lock:
        if not _loaded:
            try:
                module = _build()
                _self_check(module)
                _module = module
            except Exception as error:  # noqa: BLE001 — any failure means: use the fallback
                lines = str(error).strip().splitlines()
                _failure = f"{type(error).__name__}: {lines[0] if lines else ''}"
                log.warning(
                    "compiled matching-pursuit kernels unavailable (%s); using the numpy/torch "
                    "code",
                    _failure,
                )
            _loaded = True
    return _module


def kernel_failure() -> str | None:
    """Why the kernels are unavailable (after a failed :func:`load_kernels`), else None."""
    return _failure


#: What the kernels take; other tensors go to the numpy/torch code whatever the choice.
KERNEL_DTYPES = (torch.float32, torch.float64)


def kernels_for(kernel: str | None, like: torch.Tensor) -> ModuleType | None:
    """The compiled module that ``kernel`` (None: ``PARALLAX_PURSUIT_KERNEL``) asks for, to work
    on tensors like ``like``; None for the numpy/torch code, which also takes what the kernels do
    not (tensors on another device, half precision). ``"cpp"`` raises when the kernels are
    unavailable."""
    choice = kernel_choice() if kernel is None else kernel
    if choice not in KERNEL_CHOICES:
        raise ValueError(f"kernel must be one of {KERNEL_CHOICES}, got {choice!r}")
    if choice == "torch" or like.device.type != "cpu" or like.dtype not in KERNEL_DTYPES:
        return None
    module = load_kernels()
    if module is None and choice == "cpp":
        raise RuntimeError(f"the compiled matching-pursuit kernels are unavailable: {_failure}")
    return module
