"""Pursuit policy of §3.4: natural actor-critic with advantage parameters, softmax over pan steps.

Bhatnagar, Sutton, Ghavamzadeh & Lee, "Natural actor-critic algorithms", Automatica 2009,
algorithm 3, average-reward setting, linear in the state features φ (eq. 5, normalised as chosen
in :mod:`parallax.policy.features`), with the reward R = −(eC + eF) of eq. (6):

    J ← (1 − ζ)·J + ζ·r                 average reward
    δ = r − J + ξ·v·φ′ − v·φ            TD error (ξ = 1 textbook, < 1 active-efficient-coding)
    v ← v + α_v·δ·φ                     critic
    ψ = ((e_a − π(·|φ)) ⊗ φ) / T        compatible features, = ∇_Θ log π(a|φ)
    w ← w + α_n·(δ·ψ − ψ·(ψᵀw))         advantage weights (natural gradient estimate)
    Θ ← Γ(Θ·(1 − α_p·λ) + α_p·w)        actor, weight decay λ, optional projection Γ onto a ball
    π(a|φ) = softmax(Θφ / T) over A     eqs. (7)–(8)

:meth:`NaturalActorCritic._step` writes them. ``robot_updates`` (:data:`ROBOT_UPDATES`, the
schema's words) says how B robots' rows combine: "mean", each row's update from the same
parameters, their mean applied (J moves by the mean reward); "each" (beyond the paper), the rows
as B steps one after another, each from the parameters the previous one left: ``_step`` row by
row or, where no step is projected, the same steps through the rows' Gram matrices
(:mod:`parallax.policy.in_turn`). With B = 1 both are the equations. Invalid rows contribute
nothing; the loop learns the step across a trial's pan reset only with ``learn_reset_step``.
The settings' ranges are checked with the rest of the config (:mod:`parallax.config.validate`).
"""

from __future__ import annotations

import operator
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from parallax.checks import ROBOT_UPDATES
from parallax.geometry import ACTION_SET_DEG
from parallax.policy.features import FeatureNormalizer, PolicyInputs, all_finite
from parallax.policy.in_turn import apply_in_turn
from parallax.policy.settings import PolicyConfig

__all__ = ["PAPER_ACTIONS_DEG", "ROBOT_UPDATES", "NaturalActorCritic"]
#: The paper's pan increments in degrees (§3.4): the action set of parallax.geometry.
PAPER_ACTIONS_DEG = ACTION_SET_DEG
#: The statistics :meth:`NaturalActorCritic.update` reports as one tensor, in its order.
_STATISTICS = (
    "td_error average_reward entropy value critic_scale critic_norm advantage_norm actor_norm"
).split()


class NaturalActorCritic(nn.Module):
    """Linear natural actor-critic (Bhatnagar et al. 2009, alg. 3) choosing pan increments.

    The keywords are :class:`parallax.config.schema.PolicyConfig`'s settings, with its defaults.
    Learnt state (buffers, all in the state dict): ``critic`` v (D,), ``advantage`` w (|A|, D),
    ``actor`` Θ (|A|, D), ``average_reward`` J, ``updates`` (applied steps), ``rejected_updates``
    (steps refused as not finite), the normaliser's statistics and the sampling generator.
    """

    def __init__(
        self,
        state_dim: int,
        num_scales: int,
        *,
        seed: int,
        actions: Sequence[float] = PAPER_ACTIONS_DEG,
        critic_lr: float = PolicyConfig.critic_lr,
        advantage_lr: float = PolicyConfig.advantage_lr,
        actor_lr: float = PolicyConfig.actor_lr,
        discount: float = PolicyConfig.discount,
        reward_rate: float = PolicyConfig.reward_rate,
        weight_decay: float = PolicyConfig.weight_decay,
        temperature: float = PolicyConfig.temperature,
        feature_norm: str = PolicyConfig.feature_norm,
        zscore_horizon: int = PolicyConfig.zscore_horizon,
        eye_position_reference_m: float = PolicyConfig.eye_position_reference_m,
        reward_change_gain: float = PolicyConfig.reward_change_gain,
        actor_projection_radius: float | None = PolicyConfig.actor_projection_radius,
        robot_updates: str = PolicyConfig.robot_updates,
        initial_actor_range: float = PolicyConfig.initial_actor_range,
        initial_critic_range: float = PolicyConfig.initial_critic_range,
        learn_reset_step: bool = PolicyConfig.learn_reset_step,
    ) -> None:
        super().__init__()
        action_list = [float(a) for a in actions]
        # the config's check asks for two distinct increments; a repeated one is refused here
        if len(set(action_list)) != len(action_list):
            raise ValueError(f"actions must be distinct pan increments, got {action_list!r}")
        # the trainer's seed tree gives non-negative ints; torch would wrap a negative one
        seed = operator.index(seed)
        if seed < 0:
            raise ValueError(f"seed must be an int ≥ 0, got {seed!r}")
        self.state_dim, self.num_scales = state_dim, num_scales
        self.critic_lr, self.advantage_lr, self.actor_lr = critic_lr, advantage_lr, actor_lr
        self.discount, self.reward_rate, self.weight_decay = discount, reward_rate, weight_decay
        self.temperature, self.robot_updates = temperature, robot_updates
        self.learn_reset_step = learn_reset_step
        # Γ keeps Θ in the ball of this radius (None: the weight decay λ alone bounds Θ)
        self.actor_projection_radius = actor_projection_radius
        self.normalizer = FeatureNormalizer(state_dim, num_scales, feature_norm, zscore_horizon)
        self.inputs = PolicyInputs(self.normalizer, eye_position_reference_m, reward_change_gain)
        self.input_dim = self.inputs.input_dim
        shape = (len(action_list), self.input_dim)
        # float64 so that the pan increments sent to the robot are the configured degrees exactly.
        self.register_buffer("action_values", torch.tensor(action_list, dtype=torch.float64))
        self.register_buffer("critic", torch.zeros(self.input_dim))
        self.register_buffer("advantage", torch.zeros(shape))
        self.register_buffer("actor", torch.zeros(shape))
        self.register_buffer("average_reward", torch.zeros(()))
        self.register_buffer("updates", torch.zeros((), dtype=torch.int64))
        self.register_buffer("rejected_updates", torch.zeros((), dtype=torch.int64))
        # Ties in the greedy choice go to the smallest pan step, so an untrained (all-zero) actor
        # keeps the eye still instead of always turning it the same way.
        magnitudes = torch.tensor([abs(a) for a in action_list], dtype=torch.float64)
        order = torch.argsort(magnitudes, stable=True)
        self.register_buffer("_greedy_tie_order", order, persistent=False)
        # Sampling draws uniforms on the CPU and inverts the CDF on the module's device, so the
        # same seed gives the same actions on every device.
        self._generator = torch.Generator(device="cpu")
        self._generator.manual_seed(seed)
        if initial_actor_range or initial_critic_range:
            # Θ and v uniform in ±range, as the active-efficient-coding code starts them (its
            # weight_range); from a generator of their own, so the sampling stream stays the same
            init = torch.Generator(device="cpu").manual_seed(seed + 1)
            uniform = lambda *size: 2 * torch.rand(*size, generator=init) - 1  # noqa: E731
            self.actor.copy_(initial_actor_range * uniform(*shape))
            self.critic.copy_(initial_critic_range * uniform(self.input_dim))

    @property
    def num_actions(self) -> int:
        return int(self.action_values.shape[0])

    @property
    def feature_norm(self) -> str:
        return self.normalizer.mode

    @property
    def uses_reference_state(self) -> bool:
        """Whether :meth:`state` takes θ_ref (``feature_norm=difference``, beyond the paper)."""
        return self.inputs.uses_reference_state

    def state(
        self,
        theta: Tensor,
        reference_theta: Tensor | None,
        pans_deg: np.ndarray,
        lateral_m: float,
        reward_change: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> Tensor:
        """What the policy acts on, (B, input_dim), from what the robots observe
        (:meth:`PolicyInputs.state`)."""
        return self.inputs.state(
            theta, reference_theta, pans_deg, lateral_m, reward_change, self.actor
        )

    def features(self, states: Tensor, name: str = "phi") -> Tensor:
        """φ for raw states (B, input_dim), with the normaliser's current statistics."""
        return self.inputs.features(self.inputs.check(name, states, self.actor))

    def _policy(self, phi: Tensor) -> Tensor:
        """π(·|φ) = softmax(Θφ / T), eqs. (7)–(8), for features φ (B, D)."""
        return torch.softmax(phi @ self.actor.T / self.temperature, dim=1)

    def probabilities(self, phi: Tensor) -> Tensor:
        """π(·|φ) (B, |A|) for raw states; changes nothing."""
        return self._policy(self.features(phi))

    @torch.no_grad()
    def act(self, phi: Tensor, greedy: bool = False) -> Tensor:
        """Action indices (B,) into ``action_values``: sampled from π, or its mode if ``greedy``.
        In training mode the raw states first join the running feature statistics; in eval mode
        (``.eval()``) acting leaves every buffer as it was."""
        states = self.inputs.check("phi", phi, self.actor)
        if self.training:
            self.inputs.observe(states)
        logits = self.inputs.features(states) @ self.actor.T / self.temperature
        if greedy:
            ordered = logits[:, self._greedy_tie_order]
            return self._greedy_tie_order[ordered.argmax(dim=1)]
        uniforms = torch.rand(states.shape[0], generator=self._generator, dtype=torch.float64)
        cumulative = torch.softmax(logits.double(), dim=1).cumsum(dim=1)
        index = (cumulative < uniforms.to(logits.device).unsqueeze(1)).sum(dim=1)
        return index.clamp(max=self.num_actions - 1)

    def _rows(self, name: str, values: Any, batch: int, dtype: torch.dtype | None = None) -> Tensor:
        """``values``, one per row (B,), of ``dtype`` where given, on the module's device."""
        if not isinstance(values, Tensor) or values.shape != (batch,):
            shape = tuple(values.shape) if isinstance(values, Tensor) else type(values)
            raise ValueError(f"{name} must be a ({batch},) tensor, got {shape}")
        if dtype is not None and values.dtype != dtype:
            raise ValueError(f"{name} must be a {dtype} tensor, got {values.dtype}")
        return values.to(self.actor.device)

    @torch.no_grad()
    def update(
        self, phi: Tensor, action: Tensor, reward: Tensor, next_phi: Tensor, valid: Tensor
    ) -> dict[str, float]:
        """Algorithm 3 for the transitions (φ, a, r, φ′) of B robots, φ and φ′ as raw states.

        ``reward`` is the reward observed in φ′ (the coder's −(eC + eF) for the next image); rows
        with ``valid`` False change nothing. Returns for logging ``td_error`` (mean δ over valid
        rows, 0 when none), ``average_reward`` J, ``entropy`` (mean over all rows), ``value``
        (mean v·φ), ``critic_scale`` (mean |v·φ|, which a diverging critic inflates long before
        the actor shows it), the norms ‖v‖, ‖w‖, ‖Θ‖, ``valid_fraction``, ``rejected_updates``.
        """
        features = self.features(phi)
        batch = features.shape[0]
        next_features = self.features(next_phi, "next_phi")
        action = self._rows("action", action, batch, torch.int64)
        if batch:
            low, high = (int(bound) for bound in torch.aminmax(action))
            if low < 0 or high >= self.num_actions:
                got = f"{low}..{high}"
                raise ValueError(f"action indices must lie in [0, {self.num_actions}), got {got}")
        reward = self._rows("reward", reward, batch).to(self.actor.dtype)
        if not all_finite(reward):
            raise ValueError("reward holds non-finite values")
        valid = self._rows("valid", valid, batch, torch.bool)
        valid_count = int(valid.sum())
        probabilities = self._policy(features)
        entropy = -(probabilities * torch.log(probabilities.clamp(min=1e-30))).sum(dim=1)
        if valid_count == batch:  # every row (the loop's case): the same rows, without copies
            rows, valid_probabilities = (features, action, reward, next_features), probabilities
        else:
            rows = (features[valid], action[valid], reward[valid], next_features[valid])
            valid_probabilities = probabilities[valid]
        if self.robot_updates == "mean" or rows[0].shape[0] <= 1:
            td_error = self._step(*rows, valid_probabilities)
        else:
            # where no step is projected, the same steps through the Gram matrices; None where
            # one is not finite, which the row-by-row steps then reject on their own
            fast = apply_in_turn(self, *rows) if self.actor_projection_radius is None else None
            td_error = self._step_each(*rows) if fast is None else fast
        zero, values = torch.zeros((), device=features.device), features @ self.critic
        summary = [td_error.mean() if valid_count else zero, self.average_reward]
        summary += [entropy.mean(), values.mean(), values.abs().mean()] if batch else [zero] * 3
        summary += [torch.linalg.vector_norm(p) for p in (self.critic, self.advantage, self.actor)]
        stats = dict(zip(_STATISTICS, torch.stack(summary).tolist()))
        stats["valid_fraction"] = valid_count / batch if batch else 0.0
        stats["rejected_updates"] = float(self.rejected_updates)
        return stats

    def _step(self, phi: Tensor, a: Tensor, r: Tensor, next_phi: Tensor, pi: Tensor) -> Tensor:
        """Algorithm 3 for each of the n rows (φ, a, r, φ′, π(·|φ)) from the current parameters,
        the mean of their updates applied; returns their δ. One row: the equations exactly."""
        count = phi.shape[0]
        if count == 0:
            return phi.new_zeros(0)
        # J ← (1 − ζ)·J + ζ·r for each row, which enters its δ; the new J is their mean
        average_reward = (1 - self.reward_rate) * self.average_reward + self.reward_rate * r
        # δ = r − J + ξ·v·φ′ − v·φ
        td_error = r - average_reward + self.discount * (next_phi @ self.critic) - phi @ self.critic
        self.average_reward.copy_(average_reward.mean())
        # ψ = ((e_a − π) ⊗ φ)/T kept as its factor (e_a − π)/T, so ψᵀw = (e_a − π)·(wφ)/T
        score = -pi
        score[torch.arange(count, device=score.device), a] += 1
        score /= self.temperature
        advantage_estimate = (score * (phi @ self.advantage.T)).sum(dim=1)  # ψᵀw
        # Σ_rows (δ − ψᵀw)·ψ and Σ_rows δ·φ, divided by the rows' count below
        advantage_step = ((td_error - advantage_estimate).unsqueeze(1) * score).T @ phi
        critic_step = td_error @ phi
        if not (torch.isfinite(critic_step).all() and torch.isfinite(advantage_step).all()):
            # A diverging step would poison v, w and Θ for good (NaN logits → a constant action);
            # reject it and keep the parameters, as LM rejects a failed step.
            self.rejected_updates.add_(1)
            return td_error
        self.critic.add_(critic_step, alpha=self.critic_lr / count)  # v ← v + α_v·δ·φ
        # w ← w + α_n·(δ·ψ − ψ·(ψᵀw))
        self.advantage.add_(advantage_step, alpha=self.advantage_lr / count)
        # Θ ← Θ·(1 − α_p·λ) + α_p·w
        decay = 1 - self.actor_lr * self.weight_decay
        self.actor.mul_(decay).add_(self.advantage, alpha=self.actor_lr)
        if self.actor_projection_radius is not None:  # Γ: back onto the ball
            norm = self.actor.norm()
            if norm > self.actor_projection_radius:
                self.actor.mul_(self.actor_projection_radius / norm)
        self.updates.add_(1)
        return td_error

    def _step_each(self, phi: Tensor, a: Tensor, r: Tensor, next_phi: Tensor) -> Tensor:
        """The rows as n single-row :meth:`_step` s one after the other, each with π from the Θ
        the previous one left; returns their δ."""
        singles = [slice(i, i + 1) for i in range(phi.shape[0])]
        steps = [self._step(phi[s], a[s], r[s], next_phi[s], self._policy(phi[s])) for s in singles]
        return torch.cat(steps)

    def get_extra_state(self) -> dict[str, Any]:
        return {"generator": self._generator.get_state()}

    def set_extra_state(self, state: dict[str, Any]) -> None:
        if not isinstance(state, dict) or "generator" not in state:
            raise ValueError("policy state dict lacks the sampling generator's state")
        # a checkpoint loaded with map_location=cuda brings this CPU generator's state along
        self._generator.set_state(state["generator"].cpu())

    def extra_repr(self) -> str:
        inputs = self.inputs
        return (
            f"state_dim={self.state_dim}, actions={self.action_values.tolist()}, "
            f"α_v={self.critic_lr}, α_n={self.advantage_lr}, α_p={self.actor_lr}, "
            f"ξ={self.discount}, ζ={self.reward_rate}, λ={self.weight_decay}, "
            f"T={self.temperature}, Γ radius={self.actor_projection_radius}, "
            f"robot_updates={self.robot_updates!r}, "
            f"feature_norm={self.feature_norm!r}, zscore_horizon={self.normalizer.horizon}, "
            f"eye_position_reference_m={inputs.eye_position_reference_m}, "
            f"reward_change_gain={inputs.reward_change_gain}"
        )
