"""An executor of the paper's loop (:func:`parallax.loop.presentation`) for B robots on threads.

The loop asks it for the steps that touch the worlds and the dictionaries; :class:`Lockstep`
runs them so that rendering, encoding and the dictionary step overlap:

* the robots take their turns in groups (``env.robots_per_turn``, :func:`robot_turns`): each
  turn's frames are encoded, then its robots' transitions update the policy and the policy acts
  for them, and its worlds step (on the GL thread, where MuJoCo renders without the GIL) while
  the later turns are encoded and act. So a turn's frames render during the other turns' work,
  and the policy's turns, in which only the loop's thread works, overlap the rendering;
* a turn's robots are encoded chunk by chunk as their frames arrive (:func:`encode_chunk`: 4
  robots at a time on the CPU, all of them in one call on a GPU);
* the dictionary step of an iteration, from every turn's encoding, runs on the coder's helper
  thread from the last turn's encoding on (at a trial's first iteration, from θ(I0, I0) or the
  turn's step on: :class:`parallax.executor.Executor`), while the policy takes the last turn; the
  next iteration's first encoding waits for it, and leaving the ``with`` block waits for the last
  one — also when an error leaves it, so nothing runs on behind it.

:attr:`Lockstep.seconds` adds up where the calling thread spent its time in the lockstep:
waiting for the frames it encodes, waiting for the dictionary step, and encoding (its own scale,
and waiting for the helper's); the rest of its time is the loop's own (the policy's turn) and a
presentation's start (its worlds' resets and the references' patches). ``parallax-bench`` prints
it per lockstep iteration, to show which part holds a step up.

Every value is that of :class:`parallax.executor.InOrder`, the plain sequence on one thread — in the
same order per robot and per dictionary, so the results do not depend on the schedule
(``tests/test_experiment.py``) — with one torch thread (``train.threads=1``, the default): with
more, the matrix library may split a product of a chunk's rows otherwise than one of all rows.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from concurrent.futures import Future
from contextlib import contextmanager, suppress
from typing import Any

import torch

import parallax.envs
from parallax.coding import DictionarySteps, Encoding, MultiScaleCoder
from parallax.envs.observation import Observation
from parallax.executor import Executor, stack

#: Robots whose frames are encoded in one call on the CPU (the last chunk may be smaller): a small
#: chunk starts encoding sooner after the first frames arrive, a large one makes fewer calls.
ENCODE_CHUNK = 4


def encode_chunk(device: torch.device, robots: int) -> int:
    """How many robots' frames one encoding call takes: :data:`ENCODE_CHUNK` on the CPU, where
    encoding the first frames while the rest render keeps both cores busy; all of them elsewhere:
    on a GPU a call's time is mostly its kernel launches, much the same for 4 robots as for 64, so
    chunks of 4 would make the encoding nearly B/4 times as long (docs/performance.md)."""
    return ENCODE_CHUNK if device.type == "cpu" else max(robots, 1)


def robot_turns(robots: int, robots_per_turn: int) -> list[slice]:
    """The robots' turns (``env.robots_per_turn``): consecutive slices of that many robots, the
    last one maybe smaller; 0 puts all of them in one turn."""
    size = robots if robots_per_turn <= 0 else robots_per_turn
    return [slice(first, min(first + size, robots)) for first in range(0, robots, size)]


#: What :attr:`Lockstep.seconds` adds up, in this order.
WAITS = ("frames", "dictionary_step", "encoding")


class Lockstep(Executor):
    """One presentation of B robots' worlds stepped together; use it as a context manager.

    The robots take their turns in groups (``turns``: consecutive robot slices, in robot order):
    each iteration encodes turn 0's frames, then turn 1's, …; a turn's worlds step as soon as its
    actions are known (:meth:`step`), so they render while the later turns are encoded and act."""

    def __init__(self, envs: Sequence[Any], coder: MultiScaleCoder, turns: Sequence[slice]) -> None:
        super().__init__(envs, coder, turns)
        self._world = parallax.envs.gl_thread()
        self._futures: list[list[Future]] = [[] for _ in self.turns]  # each turn's next frames
        # a dictionary step running on the helper thread
        self._learning: Future | DictionarySteps | None = None
        #: the calling thread's seconds in each of :data:`WAITS` so far
        self.seconds = dict.fromkeys(WAITS, 0.0)

    def __exit__(self, kind: Any, error: BaseException | None, traceback: Any) -> None:
        if error is None:
            super().__exit__(kind, error, traceback)
        elif self._learning is not None:
            # it reads and writes the dictionaries: never leave it running; the error that
            # leaves the block is the one to raise
            with suppress(Exception):
                self._learning.result()

    def _reset_worlds(self) -> list[Observation]:
        """Every world resets on the GL thread; :meth:`frames` then encodes the first frames,
        turn by turn."""
        futures = [self._world.submit(env.reset) for env in self.envs]
        observations = [Observation.of(future.result().observation) for future in futures]
        self._futures = [futures[robots] for robots in self.turns]
        return observations

    def _encode(self, turn: int) -> tuple[list[Observation], list[Encoding]]:
        """The turn's robots' frames, encoded as they arrive (the first turn of an iteration
        after the running dictionary step, :meth:`Executor.frames`)."""
        futures, self._futures[turn] = self._futures[turn], []
        return self._encode_as_they_arrive(futures, self.turns[turn].start)

    def _step_worlds(self, turn: int, pan_increments: Sequence[float]) -> None:
        """Each robot of the turn turns its eyes by its increment (degrees) and renders, on the
        GL thread after the worlds already handed to it."""
        envs = self.envs[self.turns[turn]]
        self._futures[turn] = [
            self._world.submit(env.step, float(increment))
            for env, increment in zip(envs, pan_increments, strict=True)
        ]

    def _start_dictionary_step(self) -> None:
        """The coder's dictionary step from this iteration's encodings (every turn's), on its
        helper thread (CPU; elsewhere at once). Nothing may read the dictionaries until it has
        finished: the next :meth:`frames` of turn 0 waits for it."""
        self._finish_dictionary_step()
        self._learning = self.coder.learn_from_async(self._encodings)

    def _finish_dictionary_step(self) -> None:
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

    def _encode_as_they_arrive(
        self, futures: list[Future], first_robot: int = 0
    ) -> tuple[list[Observation], list[Encoding]]:
        observations: list[Observation] = []
        encodings = []
        chunk = encode_chunk(self.coder.device, len(futures))
        for first in range(0, len(futures), chunk):
            count = min(chunk, len(futures) - first)
            with self._timed("frames"):
                arrived = [future.result() for future in futures[first : first + count]]
            with self._timed("encoding"):
                seen = [Observation.of(timestep.observation) for timestep in arrived]
                images = stack([o.image for o in seen], self.coder.device)
                robots = slice(first_robot + first, first_robot + first + count)
                encodings.append(self.coder.encode_frame(images, robots))
            observations += seen
        return observations, encodings
