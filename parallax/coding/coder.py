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

from .atoms import atom_grid
from .pursuit import SparseCode
from .retina import ScaleSpec, as_gray_batch
from .scale import ScaleCoder


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
    """The coder's helper thread, one per process, started on first use: it encodes the second
    scale while the caller encodes the first, and takes the dictionary step of a lockstep."""
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

    def learn_from_async(self, encodings: Encoding | Sequence[Encoding]) -> Future:
        """:meth:`learn_from` on the helper thread (CPU; elsewhere at once), as a future.

        The caller must wait for it before it encodes again or reads the dictionaries. In a
        lockstep it runs while the policy learns and acts, when no other thread works: the
        world waits for the actions and the helper for the next frames."""
        if self.device.type != "cpu":
            done: Future = Future()
            self.learn_from(encodings)
            done.set_result(None)
            return done
        return _on_helper(self.learn_from, encodings)

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
