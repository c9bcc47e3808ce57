"""What the paper's loop (:func:`parallax.loop.presentation`) asks of the worlds and the coder.

An executor runs the steps that touch the worlds and the dictionaries (§3.2, §3.3): it resets the
B worlds (each draws its stimulus; the coder caches each I0), hands the loop each turn's
:class:`Frames` — the robots' observations and the coder's output for their images I(t) against
I0 — and steps the turn's worlds by its pan increments. It takes each iteration's dictionary step
from all its turns' encodings, offers θ(I0, I0) at a trial's first iteration (for a policy whose
state is relative to it) and moves the worlds for a route the robot chooses (§7).

:class:`InOrder` runs every step on the calling thread, in the paper's order;
:class:`parallax.lockstep.Lockstep` schedules the same steps on threads and is tested bit for bit
against it. :class:`Executor` is what both share: the order of the dictionary step with respect
to θ(I0, I0), and the route's moves.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
import torch

from parallax.coding import CoderOutput, Encoding, MultiScaleCoder
from parallax.envs.observation import Observation


def stack(images: Sequence[np.ndarray], device: torch.device) -> torch.Tensor:
    """The robots' images (I(t) or I0) as one (B, H, W, 3) tensor on ``device``."""
    return torch.from_numpy(np.stack(images)).to(device)


@dataclass(frozen=True)
class Frames:
    """A turn's robots' observations after a reset or a step, and the coder's output for their
    images I(t), computed with the dictionaries before this iteration's dictionary step."""

    turn: int  # the turn's index into the executor's turns
    robots: slice  # the turn's robots
    observations: list[Observation]
    output: CoderOutput
    #: θ(I0, I0) of these robots with the same dictionaries, offered at a trial's first iteration
    #: until the turn steps (None at the other iterations)
    reference: Callable[[], torch.Tensor] | None = None

    @property
    def starts_trial(self) -> bool:
        """Whether this is a trial's first iteration (the step into it crossed the pan's reset)."""
        return self.observations[0].iteration == 0

    @cached_property
    def pans(self) -> np.ndarray:
        """(B,) α of each robot (deg)."""
        return np.array([o.pan for o in self.observations])

    @cached_property
    def rewards(self) -> np.ndarray:
        """(B,) the coder's reward −(eC + eF) for each robot's image, in float64."""
        return self.output.reward.cpu().numpy().astype(np.float64)


class Executor:
    """B worlds (dm_control environments), the coder and the robots' turns (consecutive robot
    slices in robot order); use it as a context manager around one presentation.

    The last turn's :meth:`frames` start the iteration's dictionary step (the policy reads no
    dictionary, so it may run while the policy takes the last turn). At a trial's first iteration
    the step waits until θ(I0, I0) has been taken or the turn steps, since θ(I0, I0) is encoded
    with the dictionaries the frames were."""

    def __init__(self, envs: Sequence[Any], coder: MultiScaleCoder, turns: Sequence[slice]):
        self.envs, self.coder, self.turns = list(envs), coder, list(turns)
        #: the calling thread's seconds in each place it waits (parallax.lockstep.WAITS)
        self.seconds: dict[str, float] = {}
        self._encodings: list[Encoding] = []  # this iteration's, for its dictionary step
        self._learns = False  # whether this presentation's encodings teach the dictionaries
        self._due = False  # this iteration's dictionary step waits for θ(I0, I0) or the step
        self._started = False  # this iteration's dictionary step has started

    # --- what each executor does its own way ---------------------------------------------------
    def _reset_worlds(self) -> list[Observation]:
        raise NotImplementedError

    def _encode(self, turn: int) -> tuple[list[Observation], list[Encoding]]:
        """The turn's observations and their encodings, chunk by chunk in robot order."""
        raise NotImplementedError

    def _step_worlds(self, turn: int, pan_increments: Sequence[float]) -> None:
        raise NotImplementedError

    def _start_dictionary_step(self) -> None:
        raise NotImplementedError

    def _finish_dictionary_step(self) -> None:
        """Wait for a dictionary step still running, before anything reads the dictionaries."""

    # --- what the loop asks -------------------------------------------------------------------
    def __enter__(self) -> Executor:
        return self

    def __exit__(self, kind: Any, error: BaseException | None, traceback: Any) -> None:
        if error is None:
            self._start_due_dictionary_step()  # the last iteration's, when it was a trial's first
            self._finish_dictionary_step()

    def reset(self, learn: bool) -> None:
        """Every world draws its stimulus and the coder caches every I0; ``learn``: the
        dictionaries learn from this presentation's encodings (when the coder learns at all)."""
        self._learns, self._due = learn and self.coder.learn, False
        observations = self._reset_worlds()
        self.coder.set_reference(stack([o.reference for o in observations], self.coder.device))

    def frames(self, turn: int) -> Frames:
        """The turn's robots' frames, encoded; the first turn of an iteration encodes with the
        dictionaries the last iteration's step left."""
        if turn == 0:
            self._finish_dictionary_step()
            self._encodings, self._started = [], False
        observations, encodings = self._encode(turn)
        self._encodings += encodings
        output = CoderOutput.join([encoding.output for encoding in encodings])
        offer = None
        if observations[0].iteration == 0:  # a trial's first: θ(I0, I0) on demand
            offer = lambda: self._reference_state(turn, observations)  # noqa: E731
        frames = Frames(turn, self.turns[turn], observations, output, reference=offer)
        if self._learns and turn == len(self.turns) - 1:
            self._due = True
            if not frames.starts_trial:
                self._start_due_dictionary_step()
        return frames

    def step(self, turn: int, pan_increments: Sequence[float]) -> None:
        """Each robot of the turn turns its eyes by its increment (degrees)."""
        if turn == len(self.turns) - 1:
            self._start_due_dictionary_step()
        self._step_worlds(turn, pan_increments)

    # --- a route the robot chooses (§7) -------------------------------------------------------
    @property
    def trials(self) -> int:
        """Trials of a presentation that sweeps the worlds' list L (one: a continuous sweep)."""
        return self.envs[0].task.trials

    def start_route(self, lateral_m: float) -> None:
        """Before :meth:`reset`: the presentation is a route chosen as it goes, starting at
        ``lateral_m``."""
        for env in self.envs:
            env.task.start_route(lateral_m)

    def visit_next(self, lateral_m: float) -> None:
        """At a trial's last iteration, before the worlds step: the next trial is at
        ``lateral_m``."""
        for env in self.envs:
            env.task.visit_next(lateral_m)

    # --- θ(I0, I0) and the dictionary step -----------------------------------------------------
    def _reference_state(self, turn: int, observations: list[Observation]) -> torch.Tensor:
        if self._started:
            raise RuntimeError("θ(I0, I0) is offered at a trial's first iteration until it steps")
        images = stack([o.reference for o in observations], self.coder.device)
        state = self.coder.encode(images, self.turns[turn]).output.state
        if turn == len(self.turns) - 1:
            self._start_due_dictionary_step()
        return state

    def _start_due_dictionary_step(self) -> None:
        if self._due:
            self._due, self._started = False, True
            self._start_dictionary_step()


class InOrder(Executor):
    """Every step on this thread, in the paper's order: each turn's images encoded in one call,
    its worlds stepped as soon as it has acted, the dictionary step at once."""

    def __init__(self, envs: Sequence[Any], coder: MultiScaleCoder, turns: Sequence[slice]):
        super().__init__(envs, coder, turns)
        self.observations: list[Observation] = []  # each robot's latest

    def _reset_worlds(self) -> list[Observation]:
        self.observations = [Observation.of(env.reset().observation) for env in self.envs]
        return self.observations

    def _encode(self, turn: int) -> tuple[list[Observation], list[Encoding]]:
        robots = self.turns[turn]
        observations = self.observations[robots]
        images = stack([o.image for o in observations], self.coder.device)
        return observations, [self.coder.encode_frame(images, robots)]

    def _step_worlds(self, turn: int, pan_increments: Sequence[float]) -> None:
        robots = self.turns[turn]
        for b, increment in zip(range(robots.start, robots.stop), pan_increments, strict=True):
            self.observations[b] = Observation.of(self.envs[b].step(float(increment)).observation)

    def _start_dictionary_step(self) -> None:
        self.coder.learn_from(self._encodings)
