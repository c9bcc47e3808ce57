"""The compiled CPU kernels of the sparse coder (``pursuit_kernel.cpp``, paper §3.3, eq. 1).

Nine functions: ``gram_pursuit`` (the k Gram-form matching-pursuit steps, patch by patch),
``codes_and_residuals`` (dense codes and residuals from the picks), ``residuals_only``,
``pooled_activity`` (θ from the picks, summed in torch's order, without the dense codes; checked
per shape by :func:`parallax.coding.dictionary.exact_pooled_activity_kernel`),
``codes_times_residuals`` (the dictionary gradient's Bᵀ·R), ``dictionary_step`` (the whole
dictionary step and the next Gram matrix in one call, which keeps the GIL released throughout),
``encode_pairs`` (one scale's whole encoding in one call, likewise), ``encode_scales`` (every
scale's encoding from its pyramid images in one call, the first scale on the caller's thread and
the others on the module's own helper thread, which never runs Python) and
``start_dictionary_steps`` (every scale's dictionary step handed to that thread; its ``wait()``
gives the Gram matrices).
:func:`load_kernels` builds the C++ file on first use with ``torch.utils.cpp_extension.load``
(-O3; needs a C++ compiler and the ``ninja`` package; torch caches the build under
``~/.cache/torch_extensions`` or ``$TORCH_EXTENSIONS_DIR``, so later processes only load it),
then checks once that all of them reproduce the numpy/torch code bit for bit on random data
(:mod:`parallax.coding.native_check`, registered by the package with :func:`set_self_check`).
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
import hashlib
import logging
import os
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import torch

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
_self_check: Callable[[ModuleType], None] | None = None


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
    # The name carries a digest of the source and the flags, and the build compiles a copy of
    # the source kept in its own directory: checkouts at other paths or revisions then share a
    # build only when it is the same, and never rebuild each other's (a build's command names
    # its source file, so one source at two paths would rebuild on every switch, ~1 min each).
    source = SOURCE.read_bytes()
    digest = hashlib.sha256(source + " ".join(flags).encode()).hexdigest()[:12]
    name = f"parallax_pursuit_{capability.lower()}_{digest}"
    build_directory = _build_directory(cpp_extension, name)
    if not (build_directory / f"{name}.so").exists():
        log.info("compiling the matching-pursuit kernels into %s (once)", build_directory)
    with _exclusive(build_directory / "parallax.flock"):
        # torch's own lock file outlives a build that was killed, and then every later build
        # waits for it forever; while we hold our lock no other build of ours can be running.
        (build_directory / "lock").unlink(missing_ok=True)
        copy = build_directory / SOURCE.name
        if not copy.exists() or copy.read_bytes() != source:
            copy.write_bytes(source)
        return cpp_extension.load(
            name=name,
            sources=[str(copy)],
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


def set_self_check(check: Callable[[ModuleType], None]) -> None:
    """Registers the check :func:`load_kernels` runs on the built module before handing it out:
    it raises where the kernels disagree with the numpy/torch code. The package registers
    :func:`parallax.coding.native_check.self_check` when it is imported (that check runs the
    dictionary and pursuit code, which use this module)."""
    global _self_check
    _self_check = check


def load_kernels() -> ModuleType | None:
    """The compiled module, built and checked on the first call; None if unavailable."""
    global _loaded, _module, _failure
    if _loaded:
        return _module
    with _load_lock:
        if not _loaded:
            try:
                if _self_check is None:
                    raise RuntimeError("no self-check is registered (import parallax.coding)")
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
