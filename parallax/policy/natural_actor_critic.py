"""Pursuit policy of §3.4: natural actor-critic with advantage parameters, softmax over pan steps.

Bhatnagar, Sutton, Ghavamzadeh & Lee, "Natural actor-critic algorithms", Automatica 2009,
algorithm 3, average-reward setting, linear in the state features φ (eq. 5, normalised as chosen
in :mod:`parallax.policy.features`), with the reward R = −(eC + eF) of eq. (6):

    J ← (1 − ζ)·J + ζ·r                 average reward
    δ = r − J + ξ·v·φ′ − v·φ            TD error (ξ = 1 textbook; ξ < 1 as in the
                                        active-efficient-coding code)
    v ← v + α_v·δ·φ                     critic
    ψ = ((e_a − π(·|φ)) ⊗ φ) / T        compatible features, = ∇_Θ log π(a|φ)
    w ← w + α_n·(δ·ψ − ψ·(ψᵀw))         advantage weights (natural gradient estimate)
    Θ ← Θ·(1 − α_p·λ) + α_p·w           actor, with weight decay λ
    π(a|φ) = softmax(Θφ / T) over A     eqs. (7)–(8)

For a batch of B robots ``robot_updates`` says how their rows combine: "mean", each row gives its
own update from the same current parameters and the module applies their mean (J moves by the
mean reward); "in_turn" (beyond the paper), the rows' updates follow one another, each from the
parameters the previous one left, as B steps of the algorithm. With B = 1 both are exactly the
equations. One update path writes them (``_apply_update``); "in_turn" runs it row by row, or,
where no step is projected, the same steps through the rows' Gram matrices (``_apply_in_turn``,
tested equal to the row-by-row loop).
Rows marked invalid (the first transition after a stimulus or lateral-position change, which
would cross a reset) contribute nothing; a batch with no valid row changes nothing.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from parallax.geometry import ACTION_SET_DEG
from parallax.policy.features import FeatureNormalizer, PolicyInputs

#: The paper's pan increments in degrees (§3.4): the action set of parallax.geometry.
PAPER_ACTIONS_DEG = ACTION_SET_DEG
#: How the updates of B robots' rows combine (see the module docstring).
ROBOT_UPDATES = ("mean", "in_turn")
#: The statistics :meth:`NaturalActorCritic.update` reports as one tensor, in its order.
_STATISTICS = (
    "td_error",
    "average_reward",
    "entropy",
    "value",
    "critic_scale",
    "critic_norm",
    "advantage_norm",
    "actor_norm",
)


def _check_int(name: str, value: object, minimum: int) -> int:
    # operator.index accepts ints from NumPy or OmegaConf but refuses floats and strings.
    try:
        number = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"{name} must be an int, got {value!r}") from None
    if isinstance(value, bool) or number < minimum:
        raise ValueError(f"{name} must be an int ≥ {minimum}, got {value!r}")
    return number


def _check_positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def _check_non_negative(name: str, value: float) -> float:
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a non-negative finite number, got {value!r}")
    return float(value)


def _check_unit_interval(name: str, value: float, allow_zero: bool) -> float:
    low_ok = value >= 0 if allow_zero else value > 0
    if not (math.isfinite(value) and low_ok and value <= 1):
        interval = "[0, 1]" if allow_zero else "(0, 1]"
        raise ValueError(f"{name} must lie in {interval}, got {value!r}")
    return float(value)


class NaturalActorCritic(nn.Module):
    """Linear natural actor-critic (Bhatnagar et al. 2009, alg. 3) choosing pan increments.

    ``feature_norm`` picks the state normalisation (:mod:`parallax.policy.features`);
    ``zscore_horizon`` (states, 0 = never forget) lets its running statistics follow a drifting
    coder. Learnt state (buffers, all in the state dict): ``critic`` v (D,), ``advantage``
    w (|A|, D), ``actor`` Θ (|A|, D), ``average_reward`` J, ``updates`` (applied updates), the
    feature normaliser's running statistics, and — as extra state — the sampling generator.
    """

    def __init__(
        self,
        state_dim: int,
        num_scales: int,
        *,
        seed: int,
        actions: Sequence[float] = PAPER_ACTIONS_DEG,
        critic_lr: float = 1.0,
        advantage_lr: float = 0.1,
        actor_lr: float = 0.1,
        discount: float = 0.3,
        reward_rate: float = 0.01,
        weight_decay: float = 0.004,
        temperature: float = 1.0,
        feature_norm: str = "difference",
        zscore_horizon: int = 20000,
        eye_position_reference_m: float = 0.5,
        reward_change_gain: float = 10.0,
        actor_projection_radius: float | None = None,
        robot_updates: str = "in_turn",
        initial_actor_range: float = 0.0,
        initial_critic_range: float = 0.0,
    ) -> None:
        super().__init__()
        if robot_updates not in ROBOT_UPDATES:
            raise ValueError(f"robot_updates must be one of {ROBOT_UPDATES}, got {robot_updates!r}")
        self.robot_updates = robot_updates
        state_dim = _check_int("state_dim", state_dim, minimum=1)
        num_scales = _check_int("num_scales", num_scales, minimum=1)
        action_list = [float(a) for a in actions]
        if len(action_list) < 2 or len(set(action_list)) != len(action_list):
            raise ValueError(f"actions must hold at least two distinct values, got {action_list!r}")
        if not all(math.isfinite(a) for a in action_list):
            raise ValueError(f"actions must be finite numbers of degrees, got {action_list!r}")
        self.state_dim = state_dim
        self.num_scales = num_scales
        # Beyond the paper: one proprioceptive entry, then one for the last step's change of
        # reward, after θ (see PolicyInputs)
        eye_position_reference_m = _check_non_negative(
            "eye_position_reference_m", eye_position_reference_m
        )
        reward_change_gain = _check_non_negative("reward_change_gain", reward_change_gain)
        self.critic_lr = _check_non_negative("critic_lr", critic_lr)
        self.advantage_lr = _check_non_negative("advantage_lr", advantage_lr)
        self.actor_lr = _check_non_negative("actor_lr", actor_lr)
        self.discount = _check_unit_interval("discount", discount, allow_zero=True)
        self.reward_rate = _check_unit_interval("reward_rate", reward_rate, allow_zero=False)
        self.weight_decay = _check_non_negative("weight_decay", weight_decay)
        if self.actor_lr * self.weight_decay >= 1:
            raise ValueError(
                f"actor_lr·weight_decay must be below 1, got {self.actor_lr}·{self.weight_decay}"
            )
        self.temperature = _check_positive("temperature", temperature)
        # Algorithm 3's projection Γ keeps Θ in a compact set; here the ball of this radius
        # (None: no projection, the weight decay λ alone keeps Θ bounded).
        self.actor_projection_radius = (
            None
            if actor_projection_radius is None
            else _check_positive("actor_projection_radius", actor_projection_radius)
        )
        seed = _check_int("seed", seed, minimum=0)

        self.normalizer = FeatureNormalizer(
            state_dim, num_scales, feature_norm, _check_int("zscore_horizon", zscore_horizon, 0)
        )
        self.inputs = PolicyInputs(self.normalizer, eye_position_reference_m, reward_change_gain)
        self.input_dim = self.inputs.input_dim
        num_actions = len(action_list)
        # float64 so that the pan increments sent to the robot are the configured degrees exactly.
        self.register_buffer("action_values", torch.tensor(action_list, dtype=torch.float64))
        self.register_buffer("critic", torch.zeros(self.input_dim))
        self.register_buffer("advantage", torch.zeros(num_actions, self.input_dim))
        self.register_buffer("actor", torch.zeros(num_actions, self.input_dim))
        self.register_buffer("average_reward", torch.zeros(()))
        self.register_buffer("updates", torch.zeros((), dtype=torch.int64))
        self.register_buffer("rejected_updates", torch.zeros((), dtype=torch.int64))
        # Ties in the greedy choice go to the smallest pan step, so an untrained (all-zero) actor
        # keeps the eye still instead of always turning it the same way.
        self.register_buffer(
            "_greedy_tie_order",
            torch.argsort(
                torch.tensor([abs(a) for a in action_list], dtype=torch.float64), stable=True
            ),
            persistent=False,
        )
        # Sampling draws uniforms on the CPU and inverts the CDF on the module's device, so the
        # same seed gives the same actions on every device.
        self._generator = torch.Generator(device="cpu")
        self._generator.manual_seed(seed)
        self.initial_actor_range = _check_non_negative("initial_actor_range", initial_actor_range)
        self.initial_critic_range = _check_non_negative(
            "initial_critic_range", initial_critic_range
        )
        if self.initial_actor_range or self.initial_critic_range:
            # Θ and v drawn uniformly in ±range, as the active-efficient-coding code starts them
            # (its weight_range); from a generator of their own, so that the sampling stream
            # is the same whatever the ranges
            init = torch.Generator(device="cpu").manual_seed(seed + 1)
            uniform = lambda *shape: 2 * torch.rand(*shape, generator=init) - 1  # noqa: E731
            self.actor.copy_(self.initial_actor_range * uniform(num_actions, self.input_dim))
            self.critic.copy_(self.initial_critic_range * uniform(self.input_dim))

    @property
    def num_actions(self) -> int:
        return int(self.action_values.shape[0])

    @property
    def feature_norm(self) -> str:
        return self.normalizer.mode

    # ------------------------------------------------------------------ inputs (PolicyInputs)

    @property
    def uses_reference_state(self) -> bool:
        """Whether :meth:`state` takes θ_ref (``feature_norm=difference``, beyond the paper)."""
        return self.inputs.uses_reference_state

    def state(
        self,
        theta: torch.Tensor,
        reference_theta: torch.Tensor | None,
        pans_deg: np.ndarray,
        lateral_m: float,
        reward_change: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> torch.Tensor:
        """What the policy acts on, (B, input_dim), from what the robots observe
        (:meth:`PolicyInputs.state`)."""
        return self.inputs.state(
            theta, reference_theta, pans_deg, lateral_m, reward_change, self.actor
        )

    def features(self, states: torch.Tensor) -> torch.Tensor:
        """φ for raw states (B, input_dim), with the normaliser's current statistics."""
        return self.inputs.features(self.inputs.check("phi", states, self.actor))

    def eye_position_feature(self, pan_deg: torch.Tensor, lateral_m: float) -> torch.Tensor:
        """ν (B, 1) for pans (B,) in degrees (:meth:`PolicyInputs.eye_position_feature`)."""
        return self.inputs.eye_position_feature(pan_deg, lateral_m, self.actor)

    def reward_change_feature(
        self, rewards: Any, previous_rewards: Any, previous_increments: Any
    ) -> torch.Tensor:
        """g (B, 1) for (B,) rewards (:meth:`PolicyInputs.reward_change_feature`)."""
        return self.inputs.reward_change_feature(
            rewards, previous_rewards, previous_increments, self.actor
        )

    # ------------------------------------------------------------------ policy

    def _logits(self, features: torch.Tensor) -> torch.Tensor:
        return features @ self.actor.T / self.temperature

    def probabilities(self, phi: torch.Tensor) -> torch.Tensor:
        """π(·|φ) (B, |A|), eqs. (7)–(8); changes nothing."""
        return torch.softmax(self._logits(self.features(phi)), dim=1)

    @torch.no_grad()
    def act(self, phi: torch.Tensor, greedy: bool = False) -> torch.Tensor:
        """Action indices (B,) into ``action_values``: sampled from π, or its mode if ``greedy``.

        In training mode the raw states first join the running feature statistics (``zscore``);
        in eval mode (``.eval()``) acting leaves every buffer as it was.
        """
        states = self.inputs.check("phi", phi, self.actor)
        if self.training:
            self.normalizer.observe(states[:, : self.state_dim])
        logits = self._logits(self.inputs.features(states))
        if greedy:
            ordered = logits[:, self._greedy_tie_order]
            return self._greedy_tie_order[ordered.argmax(dim=1)]
        uniforms = torch.rand(states.shape[0], generator=self._generator, dtype=torch.float64)
        cumulative = torch.softmax(logits.double(), dim=1).cumsum(dim=1)
        index = (cumulative < uniforms.to(logits.device).unsqueeze(1)).sum(dim=1)
        return index.clamp(max=self.num_actions - 1)

    # ------------------------------------------------------------------ learning

    def _check_rows(self, name: str, values: torch.Tensor, batch: int) -> torch.Tensor:
        if not isinstance(values, torch.Tensor) or values.shape != (batch,):
            shape = tuple(values.shape) if isinstance(values, torch.Tensor) else type(values)
            raise ValueError(f"{name} must be a ({batch},) tensor, got {shape}")
        return values.to(self.actor.device)

    @torch.no_grad()
    def update(
        self,
        phi: torch.Tensor,
        action: torch.Tensor,
        reward: torch.Tensor,
        next_phi: torch.Tensor,
        valid: torch.Tensor,
    ) -> dict[str, float]:
        """One step of algorithm 3 for the transitions (φ, a, r, φ′) of B robots.

        ``reward`` is the reward observed in φ′ (the coder's −(eC + eF) for the next image);
        rows with ``valid`` False change nothing. Returns floats for logging: ``td_error`` (mean
        δ over valid rows, 0 when none), ``average_reward`` (J after the step), ``entropy``
        (mean entropy of π(·|φ) over all rows), ``value`` (mean v·φ), ``critic_scale`` (mean
        |v·φ|: the critic's scale, which a diverging critic inflates long before the actor
        shows it), ``critic_norm`` ‖v‖, ``advantage_norm`` ‖w‖,
        ``actor_norm`` ‖Θ‖ and ``valid_fraction``.
        """
        features = self.features(phi)
        batch = features.shape[0]
        next_features = self.inputs.features(self.inputs.check("next_phi", next_phi, self.actor))
        action = self._check_rows("action", action, batch)
        if action.dtype != torch.int64:
            raise ValueError(f"action must be an int64 (LongTensor) of indices, got {action.dtype}")
        if batch and (int(action.min()) < 0 or int(action.max()) >= self.num_actions):
            raise ValueError(
                f"action indices must lie in [0, {self.num_actions}), "
                f"got {action.min().item()}..{action.max().item()}"
            )
        reward = self._check_rows("reward", reward, batch).to(self.actor.dtype)
        if not bool(torch.isfinite(reward).all()):
            raise ValueError("reward holds non-finite values")
        valid = self._check_rows("valid", valid, batch)
        if valid.dtype != torch.bool:
            raise ValueError(f"valid must be a BoolTensor, got {valid.dtype}")

        probabilities = torch.softmax(self._logits(features), dim=1)
        entropy = -(probabilities * torch.log(probabilities.clamp(min=1e-30))).sum(dim=1)
        rows = (features[valid], action[valid], reward[valid], next_features[valid])
        if self.robot_updates == "mean" or rows[0].shape[0] <= 1:
            td_error = self._apply_update(*rows, probabilities[valid])
        else:
            td_error = self._apply_in_turn(*rows)
        valid_count = int(valid.sum())
        zero, values = torch.zeros((), device=features.device), features @ self.critic
        summary = [td_error.mean() if valid_count else zero, self.average_reward]
        summary += [entropy.mean(), values.mean(), values.abs().mean()] if batch else [zero] * 3
        summary += [self.critic.norm(), self.advantage.norm(), self.actor.norm()]
        stats = dict(zip(_STATISTICS, torch.stack(summary).tolist()))
        stats["valid_fraction"] = valid_count / batch if batch else 0.0
        stats["rejected_updates"] = float(self.rejected_updates)
        return stats

    def _apply_update(
        self,
        features: torch.Tensor,
        action: torch.Tensor,
        reward: torch.Tensor,
        next_features: torch.Tensor,
        probabilities: torch.Tensor,
    ) -> torch.Tensor:
        """Algorithm 3 for each of the (valid) rows given, all from the current parameters, and
        the mean of their updates applied; returns their δ. One row: the equations exactly."""
        count = features.shape[0]
        if count == 0:
            return features.new_zeros(0)
        # J ← (1 − ζ)·J + ζ·r for each row, which enters its δ; the new J is their mean
        average_reward = (1 - self.reward_rate) * self.average_reward + self.reward_rate * reward
        # δ = r − J + ξ·v·φ′ − v·φ
        td_error = (
            reward
            - average_reward
            + self.discount * (next_features @ self.critic)
            - features @ self.critic
        )
        self.average_reward.copy_(average_reward.mean())
        # ψ = ((e_a − π) ⊗ φ)/T kept as its factor (e_a − π)/T, so ψᵀw = (e_a − π)·(wφ)/T
        score = -probabilities
        score[torch.arange(count, device=score.device), action] += 1
        score /= self.temperature
        advantage_estimate = (score * (features @ self.advantage.T)).sum(dim=1)  # ψᵀw
        # Σ_rows (δ − ψᵀw)·ψ and Σ_rows δ·φ, divided by the rows' count below
        advantage_step = ((td_error - advantage_estimate).unsqueeze(1) * score).T @ features
        critic_step = td_error @ features
        if not (
            bool(torch.isfinite(critic_step).all()) and bool(torch.isfinite(advantage_step).all())
        ):
            # A diverging step would poison v, w and Θ for good (NaN logits → a constant action);
            # reject it and keep the parameters, as LM rejects a failed step.
            self.rejected_updates.add_(1)
            return td_error
        self.critic.add_(critic_step, alpha=self.critic_lr / count)  # v ← v + α_v·δ·φ
        self.advantage.add_(advantage_step, alpha=self.advantage_lr / count)
        # Θ ← Θ·(1 − α_p·λ) + α_p·w
        self.actor.mul_(1 - self.actor_lr * self.weight_decay).add_(
            self.advantage, alpha=self.actor_lr
        )
        if self.actor_projection_radius is not None:  # Γ: back onto the ball
            norm = self.actor.norm()
            if norm > self.actor_projection_radius:
                self.actor.mul_(self.actor_projection_radius / norm)
        self.updates.add_(1)
        return td_error

    def _apply_in_turn(
        self,
        features: torch.Tensor,
        action: torch.Tensor,
        reward: torch.Tensor,
        next_features: torch.Tensor,
    ) -> torch.Tensor:
        """The rows' updates one after the other, each a single-row step from the parameters the
        previous row left (π(·|φ) from the Θ it left); returns their δ.

        Every quantity a row needs (v·φ, v·φ′, wφ, Θφ) is carried for all n rows in (n,) and
        (|A|, n) arrays, moved by each update through the Gram matrices ΦΦᵀ and ΦΦ′ᵀ, so the n
        steps cost a few small numpy operations each; the parameters then take the n steps'
        sum in three products. The same numbers as :meth:`_apply_row_by_row` up to rounding;
        that loop runs instead where a step is projected or not finite."""
        if self.actor_projection_radius is not None:
            return self._apply_row_by_row(features, action, reward, next_features)
        count = features.shape[0]
        as_numpy = lambda t: t.detach().to("cpu", torch.float64).numpy()  # noqa: E731
        gram, cross = as_numpy(features @ features.T), as_numpy(features @ next_features.T)
        value, next_value = as_numpy(features @ self.critic), as_numpy(next_features @ self.critic)
        advantage_phi = as_numpy(self.advantage @ features.T)  # (|A|, n): w φ_i
        actor_phi = as_numpy(self.actor @ features.T)  # (|A|, n): Θ φ_i
        rewards, actions = as_numpy(reward), action.cpu().numpy()
        average = float(self.average_reward)
        decay = 1.0 - self.actor_lr * self.weight_decay
        td_error, gain = np.empty(count), np.empty(count)
        scores = np.empty((count, self.num_actions))
        for i in range(count):
            average = (1 - self.reward_rate) * average + self.reward_rate * rewards[i]
            td_error[i] = rewards[i] - average + self.discount * next_value[i] - value[i]
            logits = actor_phi[:, i] / self.temperature
            policy = np.exp(logits - logits.max())
            score = -policy / policy.sum()
            score[actions[i]] += 1
            score /= self.temperature
            scores[i] = score
            gain[i] = td_error[i] - score @ advantage_phi[:, i]  # δ − ψᵀw
            # this row's steps of v, w and Θ, seen from every row's features
            value += self.critic_lr * td_error[i] * gram[i]
            next_value += self.critic_lr * td_error[i] * cross[i]
            advantage_phi += self.advantage_lr * gain[i] * np.outer(score, gram[i])
            actor_phi *= decay
            actor_phi += self.actor_lr * advantage_phi
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
            return self._apply_row_by_row(features, action, reward, next_features)
        self.critic.add_(critic_step, alpha=self.critic_lr)
        self.actor.mul_(decay**count).add_(
            self.advantage, alpha=self.actor_lr * float(powers.sum())
        )
        self.actor.add_(actor_step, alpha=self.actor_lr * self.advantage_lr)
        self.advantage.add_(advantage_step, alpha=self.advantage_lr)
        self.average_reward.fill_(average)
        self.updates.add_(count)
        return like(td_error)

    def _apply_row_by_row(
        self,
        features: torch.Tensor,
        action: torch.Tensor,
        reward: torch.Tensor,
        next_features: torch.Tensor,
    ) -> torch.Tensor:
        """The rows' updates one after the other as n single-row :meth:`_apply_update` steps,
        each rejected on its own when not finite, each projected when
        ``actor_projection_radius`` is set."""
        td_errors = []
        for row in range(features.shape[0]):
            one = slice(row, row + 1)
            probabilities = torch.softmax(self._logits(features[one]), dim=1)
            td_errors.append(
                self._apply_update(
                    features[one], action[one], reward[one], next_features[one], probabilities
                )
            )
        return torch.cat(td_errors)

    # ------------------------------------------------------------------ resume

    def get_extra_state(self) -> dict[str, Any]:
        return {"generator": self._generator.get_state()}

    def set_extra_state(self, state: dict[str, Any]) -> None:
        if not isinstance(state, dict) or "generator" not in state:
            raise ValueError("policy state dict lacks the sampling generator's state")
        # a checkpoint loaded with map_location=cuda brings this CPU generator's state along
        self._generator.set_state(state["generator"].cpu())

    def extra_repr(self) -> str:
        return (
            f"state_dim={self.state_dim}, actions={self.action_values.tolist()}, "
            f"α_v={self.critic_lr}, α_n={self.advantage_lr}, α_p={self.actor_lr}, "
            f"ξ={self.discount}, ζ={self.reward_rate}, λ={self.weight_decay}, "
            f"T={self.temperature}, feature_norm={self.feature_norm!r}, "
            f"zscore_horizon={self.normalizer.horizon}, "
            f"eye_position_reference_m={self.inputs.eye_position_reference_m}, "
            f"reward_change_gain={self.inputs.reward_change_gain}, "
            f"robot_updates={self.robot_updates!r}, "
            f"initial_actor_range={self.initial_actor_range}, "
            f"initial_critic_range={self.initial_critic_range}"
        )
