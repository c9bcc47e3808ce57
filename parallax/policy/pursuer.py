"""The eye's learner over one presentation (paper §3.4, Fig. 3): what the policy sees, learns
from and does, turn by turn of robots.

A :class:`Pursuer` wraps the natural actor-critic (:mod:`parallax.policy.natural_actor_critic`)
for the loop (:func:`parallax.loop.presentation`). For each turn of robots it keeps the last step
it took, from which it learns at the next iteration: the transition (φ, a, r, φ′) with r the
coder's reward −(eC + eF) for the image the step led to (eq. 6). It owns the rules of that
bookkeeping: the step into a trial, across the pan's reset, is learnt only with
``policy.learn_reset_step``; a state relative to θ(I0, I0) (``feature_norm=difference``) takes
the executor's θ(I0, I0) at each trial's start; the reward change of the last step is a feature
(``reward_change_gain``). Frozen (``learn`` false), it neither learns nor moves the running
feature statistics.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import torch

from parallax.policy.natural_actor_critic import NaturalActorCritic

if TYPE_CHECKING:
    from parallax.executor import Frames


class Step(NamedTuple):
    """A turn's last step within the trial, for the transition the policy learns from next."""

    state: torch.Tensor  # (B, input_dim) what the policy acted on
    action: torch.Tensor  # (B,) the action indices
    rewards: np.ndarray  # (B,) the coder's rewards for the images acted on
    increments: np.ndarray  # (B,) the pan increments sent (deg)


class Pursuer:
    """The policy's turn in the loop, for the robots' ``turns`` (consecutive robot slices): use it
    as a context manager around one presentation; :meth:`see` each turn's frames, then
    :meth:`act` for it."""

    def __init__(
        self,
        policy: NaturalActorCritic,
        turns: Sequence[slice],
        *,
        learn: bool = True,
        greedy: bool = False,
    ) -> None:
        self.policy, self.learn, self.greedy = policy, bool(learn), bool(greedy)
        count = len(turns)
        self.previous: list[Step | None] = [None] * count  # each turn's last step
        self.reference: list[torch.Tensor | None] = [None] * count  # θ(I0, I0) of each turn
        # each turn's state and rewards now, to act on
        self.now: list[tuple[torch.Tensor, np.ndarray] | None] = [None] * count
        # every robot's transition is learnt (a row marked invalid would contribute nothing)
        device = policy.action_values.device
        self.valid = [torch.ones(r.stop - r.start, dtype=torch.bool, device=device) for r in turns]
        self.stat_sums: dict[str, float] = {}
        self.updates = 0
        self._was_training = policy.training

    def __enter__(self) -> Pursuer:
        self._was_training = self.policy.training
        self.policy.train(self.learn and self._was_training)
        return self

    def __exit__(self, *error: Any) -> None:
        self.policy.train(self._was_training)

    def see(self, frames: Frames) -> None:
        """The turn's robots see their encoded images I(t): the state they are in, and the
        policy learns from the step that led there."""
        turn, policy = frames.turn, self.policy
        if frames.starts_trial:  # the step into it crossed the pan's reset
            if not policy.learn_reset_step:
                self.previous[turn] = None
            if policy.uses_reference_state:
                self.reference[turn] = frames.reference()
        rewards, before = frames.rewards, self.previous[turn]
        change = None if before is None else (rewards, before.rewards, before.increments)
        body = frames.observations[0].lateral_position  # l_p, or x(t)
        state = policy.state(frames.output.state, self.reference[turn], frames.pans, body, change)
        if self.learn and before is not None:  # learn from the step into this image
            transition = (before.state, before.action, frames.output.reward, state)
            self._note(policy.update(*transition, self.valid[turn]))
        self.now[turn] = (state, rewards)

    def act(self, turn: int) -> np.ndarray:
        """The turn's pan increments (deg), from the state it saw last."""
        state, rewards = self.now[turn]
        action = self.policy.act(state, greedy=self.greedy)
        increments = self.policy.action_values[action].cpu().numpy()
        self.previous[turn] = Step(state, action, rewards, increments)
        return increments

    def statistics(self) -> dict[str, float]:
        """The mean of what the policy's updates reported (empty when it learnt nothing)."""
        return {k: v / self.updates for k, v in self.stat_sums.items()} if self.updates else {}

    def _note(self, stats: dict[str, float]) -> None:
        for k, v in stats.items():
            self.stat_sums[k] = self.stat_sums.get(k, 0.0) + float(v)
        self.updates += 1
