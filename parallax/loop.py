"""The paper's loop (§3.2, Fig. 3): one stimulus presentation, as one plain function.

For each lateral position, for each iteration, each turn of robots: encode I(t) (state θ,
reward −(eC+eF)) → the policy learns from the step into it → act → the worlds step; the
dictionary step from every turn's encoding; the pan at a trial's last iteration is q_p (with the
body sweeping L in one trial, env.motion=continuous: the pan as it passes l_p).

An executor runs the steps that touch the worlds and the dictionaries: :class:`InOrder`, every
step on this thread, or :class:`parallax.lockstep.Lockstep`, the same steps scheduled on threads
(tested bit for bit against :class:`InOrder`). A route (§7) is the strategy the loop asks "where
next?" at the end of each trial; without one the robots sweep L in order.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np
import torch

from parallax.coding import Encoding, MultiScaleCoder
from parallax.lockstep import Frames, stack_images
from parallax.parts import Parts
from parallax.presentation import Presentation, Step, Tally

#: Where next: (positions visited so far, the presentation as it stands) → an index into L, or
#: None to stop there.
Route = Callable[[list[int], Presentation], int | None]


class Executor(Protocol):
    """Runs a presentation's world and dictionary steps (a context manager)."""

    turns: list[slice]  # the robots' turns, consecutive slices in robot order
    seconds: dict[str, float]  # where the loop's thread waited (parallax.lockstep.WAITS)

    def reset(self) -> None: ...  # every world draws its stimulus; the coder caches every I0
    def frames(self, turn: int) -> Frames: ...  # the turn's images I(t), encoded
    def start_dictionary_step(self) -> None: ...  # from this iteration's encodings
    def step(self, turn: int, pan_increments: Sequence[float]) -> None: ...
    def __enter__(self) -> Executor: ...
    def __exit__(self, *error: Any) -> None: ...


def sweep(positions: int) -> Route:
    """The paper's route: every position of L, in order."""
    return lambda visited, _: len(visited) if len(visited) < positions else None


def presentation(
    parts: Parts,
    run: Executor,
    *,
    learn: bool = True,
    greedy: bool = False,
    route: Route | None = None,
    keep_view: bool = False,
) -> Presentation:
    """All robots live through one presentation; frozen (``learn`` false), acting does not move
    the policy's running feature statistics. ``route`` (one robot; §7): the position of L to go
    to next, asked before the first trial and at the end of each; None stops there."""
    was_training = parts.policy.training
    parts.policy.train(learn and was_training)
    try:
        with run:
            return _presentation(parts, run, learn, greedy, route, keep_view)
    finally:
        parts.policy.train(was_training)


def _presentation(
    parts: Parts, run: Executor, learn: bool, greedy: bool, route: Route | None, keep_view: bool
) -> Presentation:
    coder, policy, task = parts.coder, parts.policy, parts.worlds[0].task
    lateral, last_t = list(task.lateral_positions), task.trial_length - 1
    tally = Tally(len(parts.worlds), lateral, task.trial_length, route is not None, task.continuous)
    where_next = route or sweep(task.trials)  # continuous motion: one trial sweeps all of L
    p = _start(task, route, where_next([], tally.presentation(None, False)), len(parts.worlds))
    previous: list[Step | None] = [None] * len(run.turns)  # each turn's last step, to learn from
    reference: list[torch.Tensor | None] = [None] * len(run.turns)  # θ(I0, I0) of each turn
    seen: list[dict] = [{} for _ in parts.worlds]  # each robot's latest observation
    # every robot's transition is learnt (a row marked invalid would contribute nothing)
    valid = [torch.ones(r.stop - r.start, dtype=torch.bool, device=coder.device) for r in run.turns]
    visited: list[int] = []
    run.reset()  # each world: its stimulus, I0 at l0
    while p is not None:  # for each lateral position l_p
        visited.append(p)
        for t in range(task.trial_length):  # for each iteration
            for k, robots in enumerate(run.turns):
                frames = run.frames(k)  # encode I(t)
                out, seen[robots] = frames.output, frames.observations
                if t == 0:  # a new trial: the step into it crossed the pan's reset
                    if not policy.learn_reset_step:
                        previous[k] = None
                    if policy.uses_reference_state:
                        images = stack_images(frames.observations, "reference", coder.device)
                        reference[k] = coder.encode(images, robots).output.state
                if learn and coder.learn and k == len(run.turns) - 1:
                    run.start_dictionary_step()  # the policy reads no dictionary
                pans = np.array([float(o["pan"]) for o in frames.observations])
                rewards = out.reward.cpu().numpy().astype(np.float64)
                tally.encoded(frames.observations, out, pans, rewards, p, robots)
                before = previous[k]
                change = None if before is None else (rewards, before.rewards, before.increments)
                body = float(frames.observations[0]["lateral_position"])  # l_p, or x(t)
                state = policy.state(out.state, reference[k], pans, body, change)
                if learn and before is not None:  # learn from the step into this image
                    transition = (before.state, before.action, out.reward, state, valid[k])
                    tally.updated(policy.update(*transition))
                if t == last_t:  # where next, from the trial just ended (q_p)
                    if k == 0:
                        after = _next(task, route, where_next, visited, tally, seen, lateral)
                    if after is None:
                        continue
                action = policy.act(state, greedy=greedy)  # act
                increments = policy.action_values[action].cpu().numpy()
                previous[k] = Step(state, action, rewards, increments)
                run.step(k, increments)  # the worlds step
        p = after
    return tally.presentation(seen, keep_view)


def _start(task, route: Route | None, first: int | None, robots: int) -> int | None:
    """The first position; a route starts the world's episode there."""
    if route is not None:
        if robots != 1:
            raise ValueError(f"a chosen route needs env.robots=1, got {robots}")
        if first is None:
            raise ValueError("a route must visit at least one lateral position")
        task.start_route(task.lateral_positions[first])
    return first


def _next(task, route, where_next, visited, tally, seen, lateral) -> int | None:
    """The route's next position after the trial at ``visited[-1]``; the world goes there."""
    if route is None:
        return where_next(list(visited), None)
    tally.visited.append(visited[-1])
    after = where_next(list(visited), tally.presentation(seen, False))
    if after is not None:
        if after in visited:
            raise ValueError(f"the route visits position {after} of L twice")
        task.visit_next(lateral[after])
    return after


class InOrder:
    """Every step on this thread, in the paper's order: each turn's images encoded in one call,
    its worlds stepped as soon as it has acted, the dictionary step when the loop asks for it."""

    def __init__(self, envs: Sequence[Any], coder: MultiScaleCoder, turns: Sequence[slice]):
        self.envs, self.coder, self.turns = list(envs), coder, list(turns)
        self.observations: list[dict] = []
        self.encodings: list[Encoding] = []  # this iteration's, for its dictionary step
        self.seconds: dict[str, float] = {}

    def __enter__(self) -> InOrder:
        return self

    def __exit__(self, *error: Any) -> None:
        pass

    def reset(self) -> None:
        self.observations = [env.reset().observation for env in self.envs]
        self.coder.set_reference(stack_images(self.observations, "reference", self.coder.device))

    def frames(self, turn: int) -> Frames:
        if turn == 0:
            self.encodings = []
        robots = self.turns[turn]
        observations = self.observations[robots]
        images = stack_images(observations, "image", self.coder.device)
        self.encodings.append(self.coder.encode_frame(images, robots))
        return Frames(observations, self.encodings[-1].output)

    def start_dictionary_step(self) -> None:
        self.coder.learn_from(self.encodings)

    def step(self, turn: int, pan_increments: Sequence[float]) -> None:
        robots = self.turns[turn]
        for b, increment in zip(range(robots.start, robots.stop), pan_increments, strict=True):
            self.observations[b] = self.envs[b].step(float(increment)).observation
