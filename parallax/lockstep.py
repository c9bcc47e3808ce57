"""How the steps of B robots are scheduled on threads (paper §3.2, Fig. 3; no equation of its own).

:meth:`parallax.experiment.Experiment.run_presentation` reads as the paper's sequence

    render → retina → coder → policy update and act → dictionary step

and calls a :class:`Lockstep` for the parts that run on other threads:

* the worlds reset and step on the GL thread (:func:`parallax.envs.gl_thread`, MuJoCo renders
  without the GIL) while this thread encodes: the robots' frames are encoded chunk by chunk, in
  robot order, each chunk as soon as its frames are there (:func:`encode_chunk`: 4 robots at a
  time on the CPU, all of them in one call on a GPU);
* the dictionary step of an iteration runs on the coder's helper thread from
  :meth:`Lockstep.start_dictionary_step` on, while the policy learns and acts (a turn in which
  only this thread would work: the world waits for the actions) and while the next frames
  render; :meth:`Lockstep.step` waits for it before it encodes again, and leaving the ``with``
  block waits for the last one — also when an error leaves it, so no step runs on behind it.

:attr:`Lockstep.seconds` adds up where the calling thread spent its time in the lockstep:
waiting for the frames it encodes, waiting for the dictionary step, and encoding (its own scale,
and waiting for the helper's); the rest of its time is what the caller does between the calls
(the policy's turn) and a presentation's start (its worlds' resets and the references' patches).
``parallax-bench`` prints it per lockstep iteration, to show which part holds a step up.

Every value is computed as in the plain sequence, in the same order per robot and per dictionary
(``tests/test_experiment.py`` runs that sequence beside it), so the results do not depend on the
schedule — with one torch thread (``train.threads=1``, the default): with more, the matrix
library may split a product of a chunk's rows otherwise than one of all rows.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, wait
from contextlib import contextmanager
from typing import Any, NamedTuple

import numpy as np
import torch

import parallax.envs
from parallax.coding import CoderOutput, Encoding, MultiScaleCoder

#: Robots whose frames are encoded in one call on the CPU (the last chunk may be smaller): a small
#: chunk starts encoding sooner after the first frames arrive, a large one makes fewer calls.
ENCODE_CHUNK = 4


def encode_chunk(device: torch.device, robots: int) -> int:
    """How many robots' frames one encoding call takes: :data:`ENCODE_CHUNK` on the CPU, where
    encoding the first frames while the rest render keeps both cores busy; all of them elsewhere:
    on a GPU a call's time is mostly its kernel launches, much the same for 4 robots as for 64, so
    chunks of 4 would make the encoding nearly B/4 times as long (docs/performance.md)."""
    return ENCODE_CHUNK if device.type == "cpu" else max(robots, 1)


#: What :attr:`Lockstep.seconds` adds up, in this order.
WAITS = ("frames", "dictionary_step", "encoding")


class Frames(NamedTuple):
    """The robots' observations after a reset or a step, and the coder's output for their
    images (computed with the dictionaries before this iteration's dictionary step)."""

    observations: list[dict]
    output: CoderOutput
    last: bool  # the presentation's last iteration (the robots cross it together)


def stack_images(observations: Sequence[dict], key: str, device: torch.device) -> torch.Tensor:
    """The robots' ``key`` images ("image" I(t) or "reference" I0) as one (B, H, W, 3) tensor."""
    return torch.from_numpy(np.stack([o[key] for o in observations])).to(device)


class Lockstep:
    """One presentation of B robots' worlds stepped together; use it as a context manager."""

    def __init__(self, envs: Sequence[Any], coder: MultiScaleCoder) -> None:
        self.envs = list(envs)
        self.coder = coder
        self._world = parallax.envs.gl_thread()
        # the last frames' encodings, chunk by chunk, for their dictionary step
        self._encodings: list[Encoding] = []
        self._learning: Future | None = None  # a dictionary step running on the helper thread
        #: the calling thread's seconds in each of :data:`WAITS` so far
        self.seconds = dict.fromkeys(WAITS, 0.0)

    def __enter__(self) -> Lockstep:
        return self

    def __exit__(self, kind: Any, error: BaseException | None, traceback: Any) -> None:
        if error is None:
            self.finish_dictionary_step()
        elif self._learning is not None:
            wait([self._learning])  # it reads and writes the dictionaries: never leave it running

    def reset(self) -> Frames:
        """Every world draws its stimulus; the coder caches every I0, then encodes the first
        frames."""
        futures = [self._world.submit(env.reset) for env in self.envs]
        references = [future.result().observation for future in futures]
        self.coder.set_reference(stack_images(references, "reference", self.coder.device))
        return self._encode_as_they_arrive(futures)

    def step(self, pan_increments: Sequence[float]) -> Frames:
        """Each robot turns its eyes by its increment (degrees) and renders; the frames are encoded
        after the running dictionary step has finished, with the dictionaries it leaves."""
        futures = [
            self._world.submit(env.step, float(increment))
            for env, increment in zip(self.envs, pan_increments, strict=True)
        ]
        self.finish_dictionary_step()  # while the frames render
        return self._encode_as_they_arrive(futures)

    def start_dictionary_step(self) -> None:
        """The coder's dictionary step from the last frames' encoding, on its helper thread (CPU;
        elsewhere at once). Nothing may read the dictionaries until it has finished."""
        self.finish_dictionary_step()
        self._learning = self.coder.learn_from_async(self._encodings)

    def finish_dictionary_step(self) -> None:
        """Wait for the running dictionary step, if any, and raise its error, if any."""
        learning, self._learning = self._learning, None
        if learning is not None:
            with self._timed("dictionary_step"):
                learning.result()

    @contextmanager
    def _timed(self, wait: str) -> Iterator[None]:
        """Adds the seconds the block takes to :attr:`seconds` [``wait``]."""
        started = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[wait] += time.perf_counter() - started

    def _encode_as_they_arrive(self, futures: list[Future]) -> Frames:
        timesteps: list[Any] = []
        self._encodings = []
        chunk = encode_chunk(self.coder.device, len(futures))
        for first in range(0, len(futures), chunk):
            robots = slice(first, min(first + chunk, len(futures)))
            with self._timed("frames"):
                arrived = [future.result() for future in futures[robots]]
            timesteps += arrived
            with self._timed("encoding"):
                images = stack_images(
                    [ts.observation for ts in arrived], "image", self.coder.device
                )
                self._encodings.append(self.coder.encode(images, robots))
        return Frames(
            observations=[ts.observation for ts in timesteps],
            output=CoderOutput.join([encoding.output for encoding in self._encodings]),
            last=timesteps[0].last(),
        )
