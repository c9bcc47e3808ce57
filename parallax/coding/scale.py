"""One scale of the sensory coding model (paper §3.3, Fig. 5): retina + pursuit + dictionary.

A :class:`ScaleCoder` turns gray eye images into the scale's pooled activity θ^j (eqs. 2–3) and
reconstruction error e^j (eq. 4), and — when learning — takes one gradient step on its
dictionary with every patch of every image of the call. The I0 patches are cut once per stimulus
(:meth:`ScaleCoder.set_reference`) and kept in a non-persistent buffer: they follow
``.to(device)`` but stay out of ``state_dict()``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import nn

from parallax.coding.settings import CoderConfig

from . import native
from .dictionary import (
    chunks_and_step,
    exact_pooled_activity_kernel,
    gradient_step_,
    gradient_step_and_gram_,
    pooled_activity_of,
    random_dictionary,
    reconstruction_error,
)
from .pursuit import SparseCode, gram_matrix, matching_pursuit, matching_pursuit_recompute
from .retina import (
    NEAR_CONSTANT_TOLERANCE,
    ScaleSpec,
    prepare_reference,
    scale_patches,
    stack_pair,
)

#: "gram": the Gram-form pursuit, on the CPU in the compiled kernels when they can be built (see
#: ``PARALLAX_PURSUIT_KERNEL`` in :mod:`parallax.coding.native`); "gram_cpp" and "gram_torch"
#: force the kernels or the numpy/torch code, for the pursuit and the dictionary update alike
#: (same results); "recompute": correlations recomputed from the residual at every step.
PURSUITS = ("gram", "gram_cpp", "gram_torch", "recompute")
KERNELS = {"gram": None, "gram_cpp": "cpp", "gram_torch": "torch"}


@dataclass
class ScaleOutput:
    """What one scale reports for a batch of B images (computed before any dictionary update)."""

    activity: torch.Tensor  # (B, N) θ^j
    error: torch.Tensor  # (B,) e^j


class ScaleCoder(nn.Module):
    """Sparse coder of one scale. ``dictionary`` is an (N, K) buffer with atoms as rows."""

    dictionary: torch.Tensor
    reference: torch.Tensor | None

    def __init__(
        self,
        spec: ScaleSpec,
        atoms: int,
        sparsity: int,
        learning_rate: float,
        normalisation: str,
        generator: torch.Generator,
        pursuit: str = "gram",
        robot_updates: str = CoderConfig.robot_updates,
    ) -> None:
        super().__init__()
        if pursuit not in PURSUITS:  # not a setting of a run: the tests' and benchmarks' choice
            raise ValueError(f"pursuit must be one of {PURSUITS}, got {pursuit!r}")
        self.robot_updates = robot_updates
        self.spec = spec
        self.sparsity = sparsity
        self.learning_rate = learning_rate
        self.normalisation = normalisation
        self.pursuit = pursuit
        self.register_buffer("dictionary", random_dictionary(atoms, spec.dim, generator))
        self.register_buffer("reference", None, persistent=False)
        self._gram_key: tuple | None = None
        self._gram: torch.Tensor | None = None

    @property
    def atoms(self) -> int:
        return self.dictionary.shape[0]

    def gram(self) -> torch.Tensor:
        """Φ·Φᵀ, recomputed only when the dictionary changed (a frozen coder reuses it)."""
        key = self._dictionary_key()
        if self._gram is None or key != self._gram_key:
            self._gram = gram_matrix(self.dictionary)
            self._gram_key = key
        return self._gram

    def _dictionary_key(self) -> tuple:
        """Changes whenever the dictionary does (in place or replaced)."""
        dictionary = self._buffers["dictionary"]  # once: a module's buffer lookup is slow
        return (dictionary.data_ptr(), dictionary._version, dictionary.device, dictionary.dtype)

    @torch.no_grad()
    def set_reference(self, gray: torch.Tensor) -> None:
        """Cut and cache the I0 patches of (B,H,W) gray reference images."""
        raw = scale_patches(gray.to(self.dictionary.device), self.spec)
        self.reference = prepare_reference(raw, self.normalisation)

    def patch_pairs(self, gray: torch.Tensor, robots: slice = slice(None)) -> torch.Tensor:
        """γ for every patch: (B,H,W) gray current images → (B, P, K) [I0 half ; I(t) half];
        ``robots`` picks the references the images belong to (all of them by default)."""
        reference, raw = self._reference_and_raw(gray, robots)
        return stack_pair(reference, raw, self.normalisation)

    def _reference_and_raw(
        self, gray: torch.Tensor, robots: slice
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The cached I0 patches of ``robots`` and the raw patches of their (B,H,W) images."""
        reference = self.references_of(robots, gray.shape[0])
        return reference, scale_patches(gray.to(self.dictionary.device), self.spec)

    def encode(self, patches: torch.Tensor, dense_codes: bool = True) -> SparseCode:
        """Matching pursuit (eq. 1) of (M, K) patches on the current dictionary (``dense_codes``:
        see :func:`~parallax.coding.pursuit.matching_pursuit`)."""
        if self.pursuit == "recompute":
            return matching_pursuit_recompute(patches, self.dictionary, self.sparsity)
        return matching_pursuit(
            patches,
            self.dictionary,
            self.sparsity,
            self.gram(),
            kernel=KERNELS[self.pursuit],
            dense_codes=dense_codes,
        )

    @torch.no_grad()
    def learn_from(self, code: SparseCode | Sequence[SparseCode]) -> None:
        """One gradient step with all the coded patches (one code, or the codes of consecutive
        chunks of robots, in order), then unit-norm atoms again: with ``robot_updates`` "each"
        the sum of every robot's own step, with "mean" the mean of the robots' steps."""
        chunks = [code] if isinstance(code, SparseCode) else list(code)
        step = (self.dictionary, chunks, self.learning_rate, KERNELS.get(self.pursuit))
        images = self._images(chunks)
        if self.pursuit == "recompute":  # its pursuit reads no Gram matrix
            gradient_step_(*step, images=images)
            return
        # The next encoding's Gram matrix, now: in a lockstep this runs while the policy learns
        # and acts (parallax.experiment), in one compiled call where it can.
        gram = gradient_step_and_gram_(*step, images=images)
        if gram is None:  # the numpy/torch code: the step, then the Gram matrix
            gradient_step_(*step, images=images)
            gram = gram_matrix(self.dictionary)
        self._gram, self._gram_key = gram, self._dictionary_key()

    def _images(self, chunks: Sequence[SparseCode]) -> int:
        """How many images' steps the dictionary step sums: with ``robot_updates`` "each" one
        per image of the chunks, with "mean" one."""
        if self.robot_updates != "each":
            return 1
        patches = sum(chunk.residuals.shape[0] for chunk in chunks)
        return max(patches // self.spec.patch_count, 1)

    def step_size(self, chunks: Sequence[SparseCode]) -> float | None:
        """The step size :meth:`learn_from` takes with these chunks (None: no patches)."""
        return chunks_and_step(list(chunks), self.learning_rate, self._images(chunks))[1]

    def references_of(self, robots: slice, images: int) -> torch.Tensor:
        """The cached I0 patches of ``robots``, which must be ``images`` many."""
        if self.reference is None:
            raise RuntimeError("no reference image: call set_reference(I0) before encoding")
        reference = self.reference[robots]
        if images != reference.shape[0]:
            raise ValueError(f"got {images} images for {reference.shape[0]} references")
        return reference

    @torch.no_grad()
    def encode_images(
        self, gray: torch.Tensor, robots: slice = slice(None), next_reference: bool = False
    ) -> tuple[ScaleOutput, SparseCode]:
        """θ^j and e^j of (B,H,W) gray images against the references of ``robots``, and the
        sparse code a dictionary step learns from; the dictionary is left alone.
        ``next_reference``: the images then become those robots' references (the consecutive
        pairing, (I(t−1), I(t)))."""
        reference, raw = self._reference_and_raw(gray, robots)
        encoded = self._encode_pairs(reference, raw)
        if next_reference:
            self.reference[robots] = prepare_reference(raw, self.normalisation)
        return encoded

    def _encode_pairs(
        self, reference: torch.Tensor, raw: torch.Tensor
    ) -> tuple[ScaleOutput, SparseCode]:
        batch, patches = raw.shape[:2]
        # θ straight from the picks where the compiled kernel gives torch's θ exactly: the dense
        # (M, N) codes are most of the pursuit's memory traffic.
        from_picks = (
            self.pursuit != "recompute"
            and raw.device.type == "cpu"
            and exact_pooled_activity_kernel(
                patches, self.atoms, self.sparsity, raw.dtype, KERNELS[self.pursuit]
            )
        )
        if from_picks:
            # The whole encoding in one compiled call, which keeps the GIL released throughout:
            # the other scale encodes on another thread at the same time (same results).
            compiled = native.kernels_for(KERNELS[self.pursuit], raw)
            picks, coefficients, residuals, activity, error = compiled.encode_pairs(
                reference,
                raw,
                self.dictionary,
                self.gram(),
                self.sparsity,
                self.normalisation == "per_half",
                NEAR_CONSTANT_TOLERANCE,
            )
            code = SparseCode(picks, coefficients, None, residuals)
            return ScaleOutput(activity=activity, error=error), code
        pairs = stack_pair(reference, raw, self.normalisation)
        dim = pairs.shape[-1]
        code = self.encode(pairs.reshape(batch * patches, dim))
        output = ScaleOutput(
            activity=pooled_activity_of(code, batch, self.atoms),
            error=reconstruction_error(pairs, code.residuals.reshape(batch, patches, dim)),
        )
        return output, code

    def extra_repr(self) -> str:
        return (
            f"spec={self.spec}, atoms={self.atoms}, sparsity={self.sparsity}, "
            f"learning_rate={self.learning_rate}, normalisation={self.normalisation!r}, "
            f"pursuit={self.pursuit!r}"
        )
