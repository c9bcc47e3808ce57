"""What the pursuit policy acts on (§3.4): its state and the features φ of eq. (5).

:class:`PolicyInputs` builds the state from what the robots observe: the pooled activities
θ = [θC; θF] of eq. (5), and beyond the paper θ − θ_ref, the eye position and the last step's
reward change; φ is θ's part through :class:`FeatureNormalizer`, the other entries unchanged.

Why θ is normalised: pooled activities (eq. 3) are small and non-negative (about 0.006 per
entry) and share a large stimulus-dependent common component, so a linear learner fed with them
raw sees a feature vector of squared norm ≈ 0.02 whose direction is dominated by that common
part. The choices:

* ``none``          — θ as the coder returns it (the paper's form);
* ``l1_per_scale``  — each scale's block divided by its L1 norm, so every scale sums to 1 and
  a stimulus's overall activity level (contrast, texture density) no longer moves the logits;
* ``zscore``        — per entry, minus a running mean, divided by a running standard deviation,
  and the whole vector divided by √state_dim so that E‖φ‖² ≈ 1: the published step sizes
  (α_v = 1 in particular) assume features of norm about one, and a plain z-score
  (E‖φ‖² = state_dim) would make the critic's LMS step diverge;
* ``centred_unit`` / ``zscore_unit`` — minus the running mean (and z-scored), then each state
  scaled to unit norm;
* ``difference``    — beyond the paper: the states are θ(t) − θ_ref, where θ_ref is the pooled
  activity of the pair (I0, I0), i.e. of the same stimulus at zero disparity
  (:meth:`PolicyInputs.state` takes the difference). Each row is divided by
  max(‖row‖, running mean of ‖row‖): ‖φ‖ ≤ 1 keeps the α_v = 1 critic step stable, and small
  differences stay small, so at the target (I(t) ≈ I0, φ ≈ 0) the logits vanish for every
  texture and π has no preferred step. The stimulus-specific part of θ, which otherwise shifts
  the policy's fixed point by a texture-dependent offset, cancels in the difference.

The running statistics (count, mean, sum of squared deviations, in float64) are buffers, so
they travel with the state dict; they are updated only when asked (the policy does it for the
states it acts on while in training mode). With ``horizon`` > 0 the statistics forget: the past
counts for at most ``horizon`` states, so they follow the pooled activities while the coder's
dictionaries are still learning (a cumulative mean would lag further behind the longer it ran).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

# Modes that keep running statistics of the raw states.
_RUNNING_MODES = ("zscore", "centred_unit", "zscore_unit", "difference")
#: The mode whose states are differences from the zero-disparity reference θ_ref.
REFERENCE_MODE = "difference"

# Below these a per-scale L1 norm or a per-entry standard deviation counts as zero: such a block
# or entry carries no information and is mapped to zero rather than amplified rounding noise
# (a meaningful pooled activity varies by far more than 1e-9).
_TINY_L1 = 1e-12
_TINY_STD = 1e-9


class FeatureNormalizer(nn.Module):
    """Maps raw states (B, state_dim) to the features φ the learner is linear in."""

    def __init__(
        self, state_dim: int, num_scales: int, mode: str = "none", horizon: int = 0
    ) -> None:
        super().__init__()
        # the coder's sizes, known only at run time; mode and horizon are settings, which
        # parallax.config.validate checks
        if not (state_dim >= 1 and num_scales >= 1 and state_dim % num_scales == 0):
            raise ValueError(
                f"state_dim={state_dim} does not split into num_scales={num_scales} ≥ 1 blocks"
            )
        self.state_dim = state_dim
        self.num_scales = num_scales
        self.mode = mode
        self.horizon = horizon
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))
        self.register_buffer("mean", torch.zeros(state_dim, dtype=torch.float64))
        self.register_buffer("sum_sq_dev", torch.zeros(state_dim, dtype=torch.float64))
        if mode == REFERENCE_MODE:
            # running mean of ‖θ(t) − θ_ref‖; registered in this mode only, so that the other
            # modes' state dicts hold only what they use
            self.register_buffer("norm_mean", torch.zeros((), dtype=torch.float64))

    def observe(self, states: torch.Tensor) -> None:
        """Adds a batch of raw states to the running statistics (Chan et al.'s batch merge)."""
        if self.mode not in _RUNNING_MODES:
            return
        batch = states.to(self.mean.dtype)
        batch_count = float(batch.shape[0])
        if batch_count == 0:
            return
        count = float(self.count)
        if self.horizon and count > 0:
            # Forgetting: shrink the past to at most horizon − batch states' worth of evidence.
            kept = min(count, max(self.horizon - batch_count, 0.0))
            self.sum_sq_dev *= kept / count
            self.count.fill_(kept)
        total = self.count + batch_count
        if self.mode == REFERENCE_MODE:  # only the mean norm is used; skip the per-entry statistics
            norms = torch.linalg.vector_norm(batch, dim=1)
            self.norm_mean += (norms.mean() - self.norm_mean) * (batch_count / total)
            self.count.copy_(total)
            return
        batch_mean = batch.mean(dim=0)
        batch_sum_sq_dev = ((batch - batch_mean) ** 2).sum(dim=0)
        delta = batch_mean - self.mean
        self.mean += delta * (batch_count / total)
        self.sum_sq_dev += batch_sum_sq_dev + delta**2 * (self.count * batch_count / total)
        self.count.copy_(total)

    def forward(self, states: torch.Tensor) -> torch.Tensor:
        if self.mode == "none":
            return states
        if self.mode == "l1_per_scale":
            blocks = states.reshape(states.shape[0], self.num_scales, -1)
            l1 = blocks.abs().sum(dim=2, keepdim=True)
            informative = l1 > _TINY_L1
            normalised = torch.where(informative, blocks / torch.where(informative, l1, 1.0), 0.0)
            return normalised.reshape(states.shape)
        if self.mode == REFERENCE_MODE:
            differences = states.to(self.mean.dtype)
            norm = torch.linalg.vector_norm(differences, dim=1, keepdim=True)
            scale = torch.maximum(norm, self.norm_mean.expand_as(norm))
            return torch.where(scale > _TINY_L1, differences / scale.clamp(min=_TINY_L1), 0.0).to(
                states.dtype
            )
        centred = states.to(self.mean.dtype) - self.mean
        if self.mode == "centred_unit":
            return _unit_rows(centred).to(states.dtype)
        variance = self.sum_sq_dev / self.count.clamp(min=1.0)
        std = variance.sqrt()
        inverse_std = torch.where(std > _TINY_STD, 1.0 / std.clamp(min=_TINY_STD), 0.0)
        if self.mode == "zscore_unit":
            return _unit_rows(centred * inverse_std).to(states.dtype)
        scale = inverse_std / math.sqrt(self.state_dim)
        return (centred * scale).to(states.dtype)


def _unit_rows(features: torch.Tensor) -> torch.Tensor:
    """Each row scaled to unit L2 norm (an all-zero row stays zero).

    With ‖φ‖ = 1 exactly, the critic's LMS step α_v·δ·φ is stable for any α_v < 2 whatever the
    pooled activities do — a z-score alone is not bounded: an atom that was rarely active has a
    tiny running deviation, and when it becomes active its feature explodes (seen on the real
    task: the critic diverged to NaN after ~6000 updates).
    """
    norm = torch.linalg.vector_norm(features, dim=1, keepdim=True)
    return torch.where(norm > _TINY_L1, features / norm.clamp(min=_TINY_L1), 0.0)


def all_finite(values: torch.Tensor) -> bool:
    """Whether every entry is finite; on the CPU by numpy on the same memory, which answers a
    vector of a few hundred entries in a fraction of torch's per-call time (the policy asks at
    every step)."""
    if values.device.type == "cpu" and values.dtype in (torch.float32, torch.float64):
        return bool(np.isfinite(values.numpy()).all())
    return bool(torch.isfinite(values).all())


class PolicyInputs:
    """The state the policy acts on, (B, input_dim), and its features φ.

    The state is θ (B, state_dim) — θ − θ_ref when :attr:`uses_reference_state` — then the
    eye-position entry when ``eye_position_reference_m`` > 0, then the reward-change entry when
    ``reward_change_gain`` > 0 (all three beyond the paper). φ is θ's part through
    ``normalizer``; the entries after θ pass unchanged. The extra entries and checked states
    take the dtype and device of ``like``, the policy's parameters.
    """

    def __init__(
        self,
        normalizer: FeatureNormalizer,
        eye_position_reference_m: float,
        reward_change_gain: float,
    ) -> None:
        self.normalizer = normalizer
        self.state_dim = normalizer.state_dim
        self.eye_position_reference_m = eye_position_reference_m
        self.reward_change_gain = reward_change_gain
        self.eye_position_dims = 1 if eye_position_reference_m > 0 else 0
        self.reward_change_dims = 1 if reward_change_gain > 0 else 0
        self.input_dim = self.state_dim + self.eye_position_dims + self.reward_change_dims

    @property
    def uses_reference_state(self) -> bool:
        """Whether the state is θ(t) − θ_ref (``feature_norm=difference``): :meth:`state` then
        takes θ_ref, the coder's θ for the pair (I0, I0)."""
        return self.normalizer.mode == REFERENCE_MODE

    def state(
        self,
        theta: torch.Tensor,
        reference_theta: torch.Tensor | None,
        pans_deg: np.ndarray,
        lateral_m: float,
        reward_change: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
        like: torch.Tensor,
    ) -> torch.Tensor:
        """The state from the coder's θ (B, state_dim), θ_ref (B, state_dim) or None, the pans
        (B,) at the robots' shared lateral position (m) and ``reward_change``: (rewards, previous
        rewards, previous pan increments), each (B,), or None where there is no previous step
        in the trial (the entry is then 0)."""
        if (reference_theta is not None) != self.uses_reference_state:
            raise ValueError(
                f"feature_norm={self.normalizer.mode!r} "
                + ("needs θ_ref" if self.uses_reference_state else "takes no θ_ref")
            )
        state = theta if reference_theta is None else theta - reference_theta
        extra = []
        if self.eye_position_dims:
            pans = torch.as_tensor(np.asarray(pans_deg, dtype=np.float64))
            extra.append(self.eye_position_feature(pans, lateral_m, like))
        if self.reward_change_dims:
            if reward_change is None:
                extra.append(torch.zeros(state.shape[0], 1, dtype=like.dtype, device=like.device))
            else:
                extra.append(self.reward_change_feature(*reward_change, like))
        return torch.cat([state, *[e.to(state.dtype) for e in extra]], dim=1) if extra else state

    def check(self, name: str, states: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
        """``states`` as a finite (B, input_dim) tensor in ``like``'s dtype and device."""
        if (
            not isinstance(states, torch.Tensor)
            or states.ndim != 2
            or states.shape[1] != self.input_dim
        ):
            shape = tuple(states.shape) if isinstance(states, torch.Tensor) else type(states)
            raise ValueError(f"{name} must be a (B, {self.input_dim}) tensor, got {shape}")
        if not states.is_floating_point():
            raise ValueError(f"{name} must be a floating-point tensor, got {states.dtype}")
        if not all_finite(states):
            raise ValueError(f"{name} holds non-finite values")
        return states.to(device=like.device, dtype=like.dtype)

    def observe(self, states: torch.Tensor) -> None:
        """Adds checked states' θ part to the normaliser's running statistics."""
        self.normalizer.observe(states[:, : self.state_dim])

    def features(self, states: torch.Tensor) -> torch.Tensor:
        """φ for checked states, with the normaliser's current statistics."""
        if self.input_dim == self.state_dim:
            return self.normalizer(states)
        return torch.cat(
            [self.normalizer(states[:, : self.state_dim]), states[:, self.state_dim :]], dim=1
        )

    def eye_position_feature(
        self, pan_deg: torch.Tensor, lateral_m: float, like: torch.Tensor
    ) -> torch.Tensor:
        """The proprioceptive entry (B, 1) for pans (B,) in degrees at lateral position l (m).

        ν = tan(α)·d_ref / l is the nearness the pan implies (α = atan(l/d) at the target, so
        ν = d_ref/d there), clipped to [−1, 1]: the same scale at every lateral position, so
        one linear weight can tell "turned further than any plausible target" wherever the
        robot stands. A linear policy on pooled activities alone cannot: once the image pair no
        longer overlaps, a pan past the target and one short of it look alike
        (``python -m parallax.tools.analysis.landscape … --span 4``). ν is 0 at l = 0, where no
        pan is implied.
        """
        pan = torch.as_tensor(pan_deg, dtype=like.dtype, device=like.device).reshape(-1, 1)
        if abs(lateral_m) < 1e-9:
            return torch.zeros_like(pan)
        nearness = torch.tan(torch.deg2rad(pan)) * (
            self.eye_position_reference_m / float(lateral_m)
        )
        return nearness.clamp(-1.0, 1.0)

    def reward_change_feature(
        self,
        rewards: torch.Tensor,
        previous_rewards: torch.Tensor,
        previous_increments: torch.Tensor,
        like: torch.Tensor,
    ) -> torch.Tensor:
        """The reward-change entry (B, 1): how much the last pan step changed the reward, signed
        by the step's direction.

        g = clip(gain · (r_t − r_{t−1}) / |r_{t−1}| · sign(a_{t−1}), −1, 1): > 0 when turning
        left (a > 0) helped or turning right hurt, < 0 the other way, 0 after a zero step. The
        reward −(e_C + e_F) peaks at α* on both sides (``parallax.tools.analysis.landscape``),
        so g says on which side of the peak the eye is, which the pooled activities do not once
        the image pair no longer overlaps: past the target the eye would keep turning
        (runaways, docs/improvements.md §6). One weight per action can then say "go back where
        the reward fell". It is a memory of one step (an efference copy of the last movement
        and the change it made), not knowledge of the distance. Relative to |r_{t−1}| so one
        gain serves untrained and trained coders alike, whose rewards differ tenfold."""
        # numpy on the host: a handful of (B,) values per step, too few to be worth torch's
        # per-call overhead
        rewards = np.asarray(rewards, dtype=np.float64).reshape(-1)
        previous = np.asarray(previous_rewards, dtype=np.float64).reshape(-1)
        direction = np.sign(np.asarray(previous_increments, dtype=np.float64).reshape(-1))
        relative = (rewards - previous) / np.maximum(np.abs(previous), 1e-12)
        change = np.clip(self.reward_change_gain * relative * direction, -1.0, 1.0)
        return torch.from_numpy(change.reshape(-1, 1)).to(device=like.device, dtype=like.dtype)
