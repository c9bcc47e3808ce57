"""The compiled CPU kernel of the Gram-form matching pursuit (``pursuit_kernel.cpp``, paper eq. 1).

:func:`fused_pursuit_kernel` builds the C++ file on first use with
``torch.utils.cpp_extension.load`` (-O3; needs a C++ compiler and the ``ninja`` package; torch
caches the build under ``~/.cache/torch_extensions`` or ``$TORCH_EXTENSIONS_DIR``, so later
processes only load it), then checks once that it reproduces the torch path's picks and
coefficients bit for bit on random data. It returns the kernel's ``gram_pursuit`` function, or
``None`` — with one warning line saying why — when the kernel cannot be built or disagrees.

Which implementation the Gram-form pursuit uses on the CPU is chosen by the environment variable
``PARALLAX_PURSUIT_KERNEL``: ``auto`` (the default: the kernel when it is available, else the
numpy/torch loop), ``cpp`` (the kernel or an error) or ``torch`` (always the numpy/torch loop).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Callable

import torch

log = logging.getLogger(__name__)

KERNEL_ENV = "PARALLAX_PURSUIT_KERNEL"
KERNEL_CHOICES = ("auto", "cpp", "torch")
SOURCE = Path(__file__).with_name("pursuit_kernel.cpp")

#: torch's CPU kernels that round ``a + s·b·c`` as one fused multiply-add (checked at load time).
_FMA_CAPABILITIES = ("AVX2", "AVX512")

_loaded = False
_kernel: Callable | None = None
_failure: str | None = None


def kernel_choice() -> str:
    """The value of ``PARALLAX_PURSUIT_KERNEL`` (default ``auto``), validated."""
    choice = os.environ.get(KERNEL_ENV, "auto").strip().lower() or "auto"
    if choice not in KERNEL_CHOICES:
        raise ValueError(f"{KERNEL_ENV} must be one of {KERNEL_CHOICES}, got {choice!r}")
    return choice


def _build() -> Callable:
    from torch.utils import cpp_extension

    if not cpp_extension.is_ninja_available():
        raise RuntimeError("the ninja package is not installed (pip install ninja)")
    capability = torch.backends.cpu.get_cpu_capability()
    flags = ["-O3", "-ffp-contract=off"]
    if capability in _FMA_CAPABILITIES:
        # torch runs its AVX2 kernels on this CPU, so it has AVX2 and FMA too.
        flags += ["-mavx2", "-mfma", "-DPARALLAX_FMA"]
    name = f"parallax_pursuit_{capability.lower()}"
    module = cpp_extension.load(name=name, sources=[str(SOURCE)], extra_cflags=flags,
                                verbose=False)
    return module.gram_pursuit


def _self_check(kernel: Callable) -> None:
    """The kernel must give the torch path's picks and coefficients exactly, in both dtypes."""
    from .pursuit import _gram_steps_cpu

    generator = torch.Generator().manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        for atoms in (40, 37):   # whole lanes, and a tail after them
            dictionary = torch.randn(atoms, 12, generator=generator, dtype=dtype)
            dictionary /= dictionary.norm(dim=1, keepdim=True)
            patches = torch.randn(64, 12, generator=generator, dtype=dtype)
            correlations = patches @ dictionary.T
            gram = dictionary @ dictionary.T
            expected = _gram_steps_cpu(correlations.clone(), gram, 8)
            got = kernel(correlations.clone(), gram, 8)
            if not (torch.equal(got[0], expected[0]) and torch.equal(got[1], expected[1])):
                raise RuntimeError(f"its {dtype} results differ from torch's on this CPU")


def fused_pursuit_kernel() -> Callable | None:
    """The compiled ``gram_pursuit(correlations, gram, sparsity)``, or None if unavailable."""
    global _loaded, _kernel, _failure
    if not _loaded:
        _loaded = True
        try:
            kernel = _build()
            _self_check(kernel)
            _kernel = kernel
        except Exception as error:  # noqa: BLE001 — any build failure means: use the fallback
            _failure = f"{type(error).__name__}: {str(error).strip().splitlines()[0] if str(error).strip() else ''}"
            log.warning("fused matching-pursuit kernel unavailable (%s); using the numpy/torch "
                        "pursuit loop", _failure)
    return _kernel


def kernel_failure() -> str | None:
    """Why the kernel is unavailable (after a failed :func:`fused_pursuit_kernel`), else None."""
    return _failure
