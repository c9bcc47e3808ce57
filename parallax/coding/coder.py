"""The multi-scale sensory coder the trainer uses (paper §3.3–3.4, eqs. 1–6, Fig. 5).

``MultiScaleCoder`` runs one :class:`~parallax.coding.scale.ScaleCoder` per configured scale
(coarse and fine in the paper) on the same eye images and returns the reinforcement learner's
state θ = [θ^C; θ^F] (eq. 5) and reward R = −(e^C + e^F) (eq. 6). Which scales take part is a
config choice (``coder.scales=[coarse]`` is the single-scale ablation).

Dictionaries are buffers (``coders.<scale>.dictionary``, (N, K), atoms as rows), so
``state_dict()``/``load_state_dict()`` carry them and ``.to(device)`` moves them; the cached
reference patches are non-persistent and must be set again after a resume.
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from parallax.checks import default
from parallax.coding.settings import CoderConfig

from . import native
from .atoms import atom_grid
from .dictionary import MIN_ATOM_NORM, exact_pooled_activity_kernel
from .pursuit import SparseCode
from .retina import (
    NEAR_CONSTANT_TOLERANCE,
    ScaleSpec,
    as_gray_batch,
    centre_window,
    prepare_reference,
    pyramid_down,
)
from .scale import KERNELS, ScaleCoder


@dataclass
class CoderOutput:
    """Per-call result for B images, all float32 on the coder's device."""

    state: torch.Tensor  # (B, atoms·len(scales)) θ, scales in configured order
    reward: torch.Tensor  # (B,) −Σ_j e^j
    errors: dict[str, torch.Tensor]  # scale → (B,) e^j

    @staticmethod
    def join(outputs: Sequence[CoderOutput]) -> CoderOutput:
        """The outputs of consecutive chunks of robots as one output for all of them."""
        if len(outputs) == 1:
            return outputs[0]
        return CoderOutput(
            state=torch.cat([o.state for o in outputs]),
            reward=torch.cat([o.reward for o in outputs]),
            errors={
                scale: torch.cat([o.errors[scale] for o in outputs]) for scale in outputs[0].errors
            },
        )


@dataclass
class Encoding:
    """An encoding before any dictionary update: its output, and per scale the sparse code that
    :meth:`MultiScaleCoder.learn_from` takes the dictionary step with."""

    output: CoderOutput
    codes: dict[str, SparseCode]


_helper: ThreadPoolExecutor | None = None
_helper_pid: int | None = None


def _scale_helper() -> ThreadPoolExecutor:
    """The coder's helper thread where the compiled kernels do not take every scale (they have a
    helper thread of their own, :meth:`MultiScaleCoder._encode_compiled`), one per process,
    started on first use: it encodes the second scale while the caller encodes the first, and
    takes the dictionary step of a lockstep."""
    global _helper, _helper_pid
    if _helper is None or _helper_pid != os.getpid():
        _helper, _helper_pid = (
            ThreadPoolExecutor(1, thread_name_prefix="parallax-scale"),
            os.getpid(),
        )
    return _helper


def _on_helper(work: Callable[..., Any], *arguments: Any) -> Future:
    """``work(*arguments)`` on the helper thread, with the caller's torch thread count: it is per
    thread under OpenMP, and with the caller's the helper's reductions and products add up as the
    caller's would."""
    threads = torch.get_num_threads()

    def run() -> Any:
        if torch.get_num_threads() != threads:
            torch.set_num_threads(threads)
        return work(*arguments)

    return _scale_helper().submit(run)


class DictionarySteps:
    """The dictionary steps of every scale, running on the compiled kernels' helper thread
    (:meth:`MultiScaleCoder.learn_from_async`); :meth:`result` waits for them, raises their
    error if any, and hands each scale its next Gram matrix."""

    def __init__(self, pending: Any, coders: Sequence[ScaleCoder]) -> None:
        self._pending, self._coders, self._settled = pending, list(coders), False

    def result(self) -> None:
        if self._settled:
            return
        self._settled = True
        for coder, gram in zip(self._coders, self._pending.wait(), strict=True):
            coder._gram, coder._gram_key = gram, coder._dictionary_key()


def scale_seed(seed: int, scale: str) -> int:
    """The dictionary seed of one scale: depends on (seed, scale name) only, so dropping a scale
    in an ablation leaves the other scale's initial dictionary unchanged."""
    sequence = np.random.SeedSequence([seed, zlib.crc32(scale.encode("utf-8"))])
    return int(sequence.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))


class MultiScaleCoder(nn.Module):
    """Sparse coders of several scales on the same images; see the module docstring. The settings
    are coder.*'s, each defaulting to the schema's (the paper's coder) and checked by
    parallax.config; ``seed`` and ``image_size`` come at run time."""

    def __init__(
        self,
        scales: Sequence[str] = default(CoderConfig, "scales"),
        scale_specs: Mapping[str, Mapping[str, Any]] = default(CoderConfig, "scale_specs"),
        *,
        seed: int,
        image_size: int | Sequence[int],
        atoms: int = CoderConfig.atoms,
        sparsity: int = CoderConfig.sparsity,
        learning_rate: float = CoderConfig.learning_rate,
        normalisation: str = CoderConfig.normalisation,
        learn: bool = CoderConfig.learn,
        pursuit: str = "gram",
        robot_updates: str = CoderConfig.robot_updates,
        pairing: str = CoderConfig.pairing,
    ) -> None:
        super().__init__()
        scales = [str(name) for name in scales]
        # image_size is the world's, known at run time: (height, width) or one side
        height, width = (image_size, image_size) if np.ndim(image_size) == 0 else image_size
        coders = {}
        for name in scales:
            spec = ScaleSpec.from_mapping(scale_specs[name])
            if spec.window > min(height, width):
                raise ValueError(
                    f"scale_specs.{name}.window={spec.window} does not fit in "
                    f"image_size={image_size!r}"
                )
            generator = torch.Generator().manual_seed(scale_seed(int(seed), name))
            coders[name] = ScaleCoder(
                spec,
                int(atoms),
                int(sparsity),
                float(learning_rate),
                normalisation,
                generator,
                pursuit,
                robot_updates,
            )
        self.scales = scales
        self.atoms = int(atoms)
        self.learn = bool(learn)
        self.normalisation = normalisation
        self.pairing = str(pairing)
        self.coders = nn.ModuleDict(coders)
        self._compiled_key: tuple | None = None
        self._compiled: Any = None

    @property
    def state_dim(self) -> int:
        return self.atoms * len(self.scales)

    @property
    def dictionaries(self) -> dict[str, torch.Tensor]:
        """scale → (N, K) dictionary, atoms as rows (first K/2 elements: the I0 half)."""
        return {name: self.coders[name].dictionary for name in self.scales}

    @property
    def device(self) -> torch.device:
        return self.coders[self.scales[0]].dictionary.device

    @torch.no_grad()
    def set_reference(self, reference: Any) -> None:
        """Cache the I0 patches of every scale; ``reference`` is (B,H,W,3) RGB or (B,H,W) gray."""
        gray = as_gray_batch(reference, self.device)
        for name in self.scales:
            self.coders[name].set_reference(gray)

    @torch.no_grad()
    def encode(
        self, images: Any, robots: slice = slice(None), next_reference: bool = False
    ) -> Encoding:
        """Encode I(t) against the cached I0 of ``robots`` (all by default), without learning;
        ``next_reference``: the images then become those robots' references.

        A lockstep may encode its robots chunk by chunk as their frames arrive and then learn from
        all the chunks at once: the outputs and the dictionary step are those of one call.
        """
        gray = as_gray_batch(images, self.device)
        compiled = self._compiled_scales()
        if compiled is not None:
            return self._encode_compiled(compiled, gray, robots, next_reference)
        encoded = self._each_scale(
            lambda name: self.coders[name].encode_images(gray, robots, next_reference)
        )
        errors = {name: output.error for name, (output, _) in encoded.items()}
        state = torch.cat([encoded[name][0].activity for name in self.scales], dim=1)
        reward = -torch.stack(list(errors.values())).sum(dim=0)
        return Encoding(
            output=CoderOutput(state=state, reward=reward, errors=errors),
            codes={name: code for name, (_, code) in encoded.items()},
        )

    def _compiled_scales(self) -> Any:
        """The compiled kernels' module where every scale's encoding and dictionary step run
        there, all scales in one call (:meth:`_encode_compiled`, :meth:`learn_from_async`); else
        None, and each scale runs its own code. Decided once per kernel choice, torch thread
        count and dtype: θ comes from the picks only where that gives torch's θ exactly."""
        first = self.coders[self.scales[0]].dictionary
        key = (native.kernel_choice(), torch.get_num_threads(), first.dtype, first.device)
        if key != self._compiled_key:
            self._compiled_key, self._compiled = key, self._find_compiled()
        return self._compiled

    def _find_compiled(self) -> Any:
        coders = [self.coders[name] for name in self.scales]
        if any(coder.pursuit not in ("gram", "gram_cpp") for coder in coders):
            return None
        first = coders[0].dictionary
        modules = {native.kernels_for(KERNELS[coder.pursuit], first) for coder in coders}
        if len(modules) != 1 or None in modules:
            return None
        for coder in coders:
            dictionary = coder.dictionary
            if (
                dictionary.dtype != first.dtype
                or not dictionary.is_contiguous()
                or not exact_pooled_activity_kernel(
                    coder.spec.patch_count,
                    coder.atoms,
                    coder.sparsity,
                    dictionary.dtype,
                    KERNELS[coder.pursuit],
                )
            ):
                return None
        return modules.pop()

    def _encode_compiled(
        self, compiled: Any, gray: torch.Tensor, robots: slice, next_reference: bool
    ) -> Encoding:
        """:meth:`encode` in one compiled call, the same numbers: the first scale on this thread
        and the others on the kernels' helper thread, neither holding the GIL."""
        coders = [self.coders[name] for name in self.scales]
        references = [coder.references_of(robots, gray.shape[0]) for coder in coders]
        state, reward, encoded = compiled.encode_scales(
            references,
            [
                pyramid_down(centre_window(gray, c.spec.window), c.spec.pyramid_levels)
                for c in coders
            ],
            [coder.spec.patch for coder in coders],
            [coder.spec.stride for coder in coders],
            [coder.dictionary for coder in coders],
            [coder.gram() for coder in coders],
            coders[0].sparsity,
            self.normalisation == "per_half",
            NEAR_CONSTANT_TOLERANCE,
        )
        if next_reference:
            for coder, scale in zip(coders, encoded):
                coder.reference[robots] = prepare_reference(scale[5], self.normalisation)
        return Encoding(
            output=CoderOutput(
                state=state,
                reward=reward,
                errors={name: scale[4] for name, scale in zip(self.scales, encoded)},
            ),
            codes={
                name: SparseCode(scale[0], scale[1], None, scale[2])
                for name, scale in zip(self.scales, encoded)
            },
        )

    def encode_frame(self, images: Any, robots: slice = slice(None)) -> Encoding:
        """Encode the robots' newest images I(t) in the configured pairing: against I0
        (reference), or against each robot's previous image, which I(t) then replaces
        (consecutive; the cache holds I0 after :meth:`set_reference`, so I(−1) is I0)."""
        if self.pairing == "consecutive":
            return self.encode(images, robots, next_reference=True)
        return self.encode(images, robots)

    @torch.no_grad()
    def learn_from(self, encodings: Encoding | Sequence[Encoding]) -> None:
        """One dictionary step per scale from an encoding, or from the encodings of consecutive
        chunks of robots in robot order (exactly the step of their joint encoding)."""
        chunks = [encodings] if isinstance(encodings, Encoding) else list(encodings)
        # One scale after the other, on one thread: in a lockstep this runs (on the helper
        # thread, see learn_from_async) while the world renders on the other core, which a
        # second thread for the second scale would take from it.
        for name in self.scales:
            self.coders[name].learn_from([chunk.codes[name] for chunk in chunks])

    def learn_from_async(
        self, encodings: Encoding | Sequence[Encoding]
    ) -> Future | DictionarySteps:
        """:meth:`learn_from` on the helper thread (CPU; elsewhere at once); its ``result()``
        waits for it and raises its error, if any.

        The caller must wait for it before it encodes again or reads the dictionaries. In a
        lockstep it runs while the policy learns and acts, when no other thread works: the
        world waits for the actions and the helper for the next frames."""
        if self.device.type != "cpu":
            done: Future = Future()
            self.learn_from(encodings)
            done.set_result(None)
            return done
        compiled = self._compiled_scales()
        steps = None if compiled is None else self._step_sizes(encodings)
        if steps is None:
            return _on_helper(self.learn_from, encodings)
        chunks = [encodings] if isinstance(encodings, Encoding) else list(encodings)
        codes = {name: [chunk.codes[name] for chunk in chunks] for name in self.scales}
        coders = [self.coders[name] for name in self.scales]
        pending = compiled.start_dictionary_steps(
            [coder.dictionary for coder in coders],
            [[code.atom_indices for code in codes[name]] for name in self.scales],
            [[code.coefficients for code in codes[name]] for name in self.scales],
            [[code.residuals for code in codes[name]] for name in self.scales],
            steps,
            MIN_ATOM_NORM,
        )
        return DictionarySteps(pending, coders)

    def _step_sizes(self, encodings: Encoding | Sequence[Encoding]) -> list[float] | None:
        """Each scale's dictionary step size for these encodings (ScaleCoder.learn_from's);
        None where a scale has no patches to learn from."""
        chunks = [encodings] if isinstance(encodings, Encoding) else list(encodings)
        steps = [
            self.coders[name].step_size([chunk.codes[name] for chunk in chunks])
            for name in self.scales
        ]
        return None if None in steps else steps

    def _each_scale(self, work: Callable[[str], Any]) -> dict[str, Any]:
        """``work(scale)`` for every scale, the first on this thread and the others on a helper
        thread at the same time (CPU only): the scales share nothing, and their matrix products
        and kernels release the GIL, so a second core encodes the fine scale while this one does
        the coarse (at B = 1 the world waits for the encoding, so that core is free)."""
        if len(self.scales) == 1 or self.device.type != "cpu":
            return {name: work(name) for name in self.scales}
        others = {name: _on_helper(work, name) for name in self.scales[1:]}
        first = {self.scales[0]: work(self.scales[0])}
        return {**first, **{name: future.result() for name, future in others.items()}}

    @torch.no_grad()
    def forward(self, images: Any, learn: bool | None = None) -> CoderOutput:
        """Encode I(t) against the cached I0; with learning on, then one dictionary step per scale.

        The outputs are those of the encoding before the update.
        """
        learn = self.learn if learn is None else bool(learn)
        encoding = self.encode(images)
        if learn:
            self.learn_from(encoding)
        return encoding.output

    def atom_grid(self, scale: str, **options: Any) -> np.ndarray:
        """uint8 (H, W) picture of ``scale``'s atoms as (I0-half | I(t)-half) pairs; see
        :func:`parallax.coding.atoms.atom_grid` for the options."""
        if scale not in self.coders:
            raise ValueError(f"unknown scale {scale!r}; this coder has {self.scales}")
        return atom_grid(self.coders[scale].dictionary, self.coders[scale].spec.patch, **options)

    def extra_repr(self) -> str:
        return f"scales={self.scales}, learn={self.learn}, state_dim={self.state_dim}"
