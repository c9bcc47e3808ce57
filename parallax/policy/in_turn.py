"""The policy's "each" mode (§3.4, beyond the paper) in a few products: B robots' rows as B steps
of algorithm 3 (Bhatnagar et al. 2009), one after another, without B passes over the parameters.

Each row's step needs only v·φ, v·φ′, wφ and Θφ of its own row, and a step moves those of every
other row through the rows' Gram matrices ΦΦᵀ and ΦΦ′ᵀ: carried for all n rows in (n,) and
(|A|, n) arrays, the n steps cost a few small numpy operations each, and the parameters then take
the n steps' sum in three products. The same numbers as
:meth:`parallax.policy.natural_actor_critic.NaturalActorCritic._step` applied row by row, up to
rounding (``tests/policy/test_in_turn.py``). It has no projection Γ: a projected policy takes its
rows one by one.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


@torch.no_grad()
def apply_in_turn(
    policy: nn.Module,
    features: torch.Tensor,
    action: torch.Tensor,
    reward: torch.Tensor,
    next_features: torch.Tensor,
) -> torch.Tensor | None:
    """The rows' steps one after the other, each from the parameters the previous row left (π(·|φ)
    from the Θ it left), applied to ``policy`` (a NaturalActorCritic); returns their δ. Returns
    None and changes nothing where a step is not finite: the rows one by one then reject such a
    step on its own."""
    count = features.shape[0]
    as_numpy = lambda t: t.detach().to("cpu", torch.float64).numpy()  # noqa: E731
    gram, cross = as_numpy(features @ features.T), as_numpy(features @ next_features.T)
    value = as_numpy(features @ policy.critic)
    next_value = as_numpy(next_features @ policy.critic)
    advantage_phi = as_numpy(policy.advantage @ features.T)  # (|A|, n): w φ_i
    actor_phi = as_numpy(policy.actor @ features.T)  # (|A|, n): Θ φ_i
    rewards, actions = as_numpy(reward), action.cpu().numpy()
    average = float(policy.average_reward)
    rate, temperature = policy.reward_rate, policy.temperature
    decay = 1.0 - policy.actor_lr * policy.weight_decay
    td_error, gain = np.empty(count), np.empty(count)
    scores = np.empty((count, policy.num_actions))
    for i in range(count):
        average = (1 - rate) * average + rate * rewards[i]
        td_error[i] = rewards[i] - average + policy.discount * next_value[i] - value[i]
        logits = actor_phi[:, i] / temperature
        probabilities = np.exp(logits - logits.max())
        score = -probabilities / probabilities.sum()
        score[actions[i]] += 1
        score /= temperature
        scores[i] = score
        gain[i] = td_error[i] - score @ advantage_phi[:, i]  # δ − ψᵀw
        # this row's steps of v, w and Θ, seen from every row's features
        value += policy.critic_lr * td_error[i] * gram[i]
        next_value += policy.critic_lr * td_error[i] * cross[i]
        advantage_phi += policy.advantage_lr * gain[i] * np.outer(score, gram[i])
        actor_phi *= decay
        actor_phi += policy.actor_lr * advantage_phi
    # Θ_n = dⁿΘ_0 + α_p Σ_m d^(n−m) w_m, with w_m = w_0 + α_n Σ_(j≤m) gain_j·ψ_j
    powers = decay ** np.arange(count - 1, -1, -1)  # d^(n−m), m = 1..n
    tails = np.cumsum(powers[::-1])[::-1]  # Σ_(m≥j) d^(n−m)
    like = lambda a: torch.as_tensor(a, dtype=features.dtype, device=features.device)  # noqa: E731
    critic_step = like(td_error) @ features
    advantage_step = (like(gain[:, None] * scores)).T @ features
    actor_step = (like((gain * tails)[:, None] * scores)).T @ features
    if not all(
        bool(torch.isfinite(step).all()) for step in (critic_step, advantage_step, actor_step)
    ):
        return None
    policy.critic.add_(critic_step, alpha=policy.critic_lr)
    policy.actor.mul_(decay**count).add_(
        policy.advantage, alpha=policy.actor_lr * float(powers.sum())
    )
    policy.actor.add_(actor_step, alpha=policy.actor_lr * policy.advantage_lr)
    policy.advantage.add_(advantage_step, alpha=policy.advantage_lr)
    policy.average_reward.fill_(average)
    policy.updates.add_(count)
    return like(td_error)
