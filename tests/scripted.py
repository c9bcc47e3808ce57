"""Stand-ins for the worlds and the coder, for fast tests of the loop and its parts: a world
that keeps only the task's bookkeeping (pan, trial, position) and a coder that draws its outputs
from a seeded generator and notes every call."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from types import SimpleNamespace

import numpy as np
import torch

from parallax.coding import CoderOutput, Encoding
from parallax.executor import Frames, InOrder
from parallax.policy import NaturalActorCritic

STATE_DIM = 3
IMAGE = np.zeros((2, 2, 3), dtype=np.uint8)


class ScriptedWorld:
    """One robot's world reduced to the task's bookkeeping: each step turns the pan by its
    increment; after a trial's last iteration the robot is at the next position with pan 0. The
    target pan at l is 10·l degrees. Also its own ``task``."""

    continuous = False

    def __init__(self, lateral: Sequence[float], trial_length: int, distance: float = 5.0):
        self.lateral_positions = tuple(lateral)
        self.trial_length, self.distance = trial_length, distance
        self.episode, self.pending_route = list(lateral), None
        self.position = self.iteration = 0
        self.pan = 0.0
        self.moves: list[tuple] = []  # start_route, reset, visit_next, in order
        self.seen: list[tuple[int, int, float]] = []  # (position index, iteration, pan) handed out

    @property
    def task(self) -> ScriptedWorld:
        return self

    @property
    def trials(self) -> int:
        return len(self.lateral_positions)

    def start_route(self, lateral_m: float) -> None:
        self.moves.append(("start_route", lateral_m))
        self.pending_route = lateral_m

    def visit_next(self, lateral_m: float) -> None:
        assert self.iteration == self.trial_length - 1, "visit_next at a trial's last iteration"
        self.moves.append(("visit_next", lateral_m))
        self.episode = [*self.episode[: self.position + 1], lateral_m]

    def reset(self) -> SimpleNamespace:
        self.moves.append(("reset",))
        routed = self.pending_route is not None
        self.episode = [self.pending_route] if routed else list(self.lateral_positions)
        self.pending_route, self.position, self.iteration, self.pan = None, 0, 0, 0.0
        return self._timestep()

    def step(self, increment: float) -> SimpleNamespace:
        self.pan += increment
        if self.iteration < self.trial_length - 1:
            self.iteration += 1
        else:
            self.position, self.iteration, self.pan = self.position + 1, 0, 0.0
        return self._timestep()

    def _timestep(self) -> SimpleNamespace:
        lateral = self.episode[self.position]
        self.seen.append((self.position, self.iteration, self.pan))
        observation = OrderedDict(
            reference=IMAGE,
            image=IMAGE,
            pan=np.float64(self.pan),
            target_pan=np.float64(10.0 * lateral),
            distance=np.float64(self.distance),
            lateral_position=np.float64(lateral),
            position_index=np.int32(self.position),
            iteration=np.int32(self.iteration),
            texture_index=np.int32(0),
        )
        return SimpleNamespace(observation=observation)


class ScriptedCoder:
    """The coder's interface, its outputs drawn from a seeded generator; ``calls`` notes what was
    asked, in order: "I0" (the references cached), "I(t)", "θ(I0, I0)", "dictionary step"."""

    device = torch.device("cpu")

    def __init__(self, learn: bool = True, seed: int = 0) -> None:
        self.learn = learn
        self.generator = torch.Generator().manual_seed(seed)
        self.calls: list[str] = []

    def set_reference(self, images: torch.Tensor) -> None:
        self.calls.append("I0")

    def encode_frame(self, images: torch.Tensor, robots: slice) -> Encoding:
        self.calls.append("I(t)")
        return self._encoding(images.shape[0])

    def encode(self, images: torch.Tensor, robots: slice) -> Encoding:
        self.calls.append("θ(I0, I0)")
        return self._encoding(images.shape[0])

    def learn_from(self, encodings: Sequence[Encoding]) -> None:
        self.calls.append("dictionary step")

    def _encoding(self, count: int) -> Encoding:
        state = torch.rand(count, STATE_DIM, generator=self.generator)
        reward = -torch.rand(count, generator=self.generator)
        output = CoderOutput(state=state, reward=reward, errors={"coarse": -reward})
        return Encoding(output=output, codes={})


def policy(**settings) -> NaturalActorCritic:
    """A small policy over the scripted coder's states."""
    return NaturalActorCritic(STATE_DIM, num_scales=1, seed=0, **settings)


def scripted(
    robots: int = 1,
    lateral: Sequence[float] = (0.05, 0.1, 0.15),
    trial_length: int = 4,
    per_turn: int = 0,
    learn: bool = True,
    **settings,
) -> tuple[SimpleNamespace, InOrder]:
    """The parts a presentation needs (scripted worlds, a small policy) and an InOrder executor
    over them with a scripted coder; ``settings`` are the policy's."""
    from parallax.lockstep import robot_turns

    worlds = [ScriptedWorld(lateral, trial_length) for _ in range(robots)]
    coder = ScriptedCoder(learn=learn)
    parts = SimpleNamespace(worlds=worlds, coder=coder, policy=policy(**settings))
    return parts, InOrder(worlds, coder, robot_turns(robots, per_turn))


def frames(
    iteration: int,
    pans: Sequence[float],
    rewards: Sequence[float],
    turn: int = 0,
    first_robot: int = 0,
    lateral: float = 0.1,
) -> Frames:
    """A turn's frames at ``iteration``, its robots (from ``first_robot`` on) at ``pans`` with the
    coder's ``rewards``; θ is 1 everywhere, and no θ(I0, I0) is offered."""
    from parallax.envs.observation import Observation

    observations = [
        Observation(IMAGE, IMAGE, float(pan), 1.0, 5.0, lateral, 0, iteration, 0) for pan in pans
    ]
    count = len(pans)
    reward = torch.tensor(rewards, dtype=torch.float32)
    output = CoderOutput(state=torch.ones(count, STATE_DIM), reward=reward, errors={})
    return Frames(turn, slice(first_robot, first_robot + count), observations, output)
