"""The pursuit policy's settings (policy.*; paper §3.4, eqs. 5–8) beside their checks.

Every setting of the natural actor-critic as a typed dataclass field with its one default, the
choices it allows, and the checks of the values a type cannot rule out (parallax.checks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from omegaconf import MISSING

from parallax.checks import ROBOT_UPDATES, Checks
from parallax.geometry import ACTION_SET_DEG

#: policy.feature_norm: how θ becomes the features φ (parallax.policy.features).
FEATURE_NORMS = ("none", "l1_per_scale", "zscore", "centred_unit", "zscore_unit", "difference")


@dataclass
class PolicyConfig:
    """Pursuit policy (§3.4, eqs. 5–8): natural actor-critic, Bhatnagar et al. 2009 algorithm 3,
    average reward, softmax over pan increments (step-size names as in NaturalActorCritic)."""

    _target_: str = "parallax.policy.NaturalActorCritic"
    #: Filled by the trainer: the coder's state size (2 scales × 288 bases = 576).
    state_dim: int = MISSING
    #: Filled by the trainer: the coder's number of scales.
    num_scales: int = MISSING
    #: The action set A, pan increments in degrees (§3.4).
    actions: list[float] = field(default_factory=lambda: list(ACTION_SET_DEG))
    #: α_v, the critic's step size (the paper gives no step sizes).
    critic_lr: float = 1.0
    #: α_n, the advantage weights' step size (the published pursuit setting: 0.025).
    advantage_lr: float = 0.1
    #: α_p, the actor's step size (published: 0.002, with which Θ approaches w/λ with the time
    #: constant 1/(α_p·λ) = 50 000 updates).
    actor_lr: float = 0.1
    #: ξ in δ = r − J + ξ·v·φ′ − v·φ (algorithm 3 has 1; 0.3 as in active-efficient-coding code).
    discount: float = 0.3
    #: ζ, the average reward's step size.
    reward_rate: float = 0.01
    #: λ, the actor's weight decay: at rest the logits are ≈ advantage/λ, so a smaller λ gives a
    #: sharper policy (published 0.01).
    weight_decay: float = 0.004
    #: T of the softmax, eq. (7).
    temperature: float = 1.0
    #: How θ becomes the features φ (parallax.policy.features): none (θ as in eq. 5) |
    #: l1_per_scale | zscore | centred_unit | zscore_unit | difference. difference (beyond the
    #: paper): θ(t) − θ(I0, I0), the state relative to the same stimulus at zero disparity,
    #: scaled to norm ≤ 1; it removes texture-dependent offsets.
    feature_norm: str = "difference"
    #: States (robots × steps) the running feature statistics of the normalisations beyond the
    #: paper remember, so that they follow the drifting pooled activities; 0: all of them.
    zscore_horizon: int = 20000
    #: Beyond the paper: d_ref (m) > 0 adds the eye's own position as one more feature,
    #: ν = tan(pan)·d_ref/l clipped to [−1, 1], so one weight can say "turned too far" (0: off).
    eye_position_reference_m: float = 0.5
    #: Beyond the paper: gain > 0 adds the last pan step's relative change of reward, signed by
    #: the step's direction, clip(gain·(r_t − r_{t−1})/|r_{t−1}|·sign(a_{t−1}), −1, 1), as one
    #: more feature: the reward peaks at α*, so it tells a linear policy which way the peak lies
    #: (0: off).
    reward_change_gain: float = 10.0
    #: Algorithm 3's projection Γ of the actor parameters Θ onto the ball of this radius after
    #: each update (Bhatnagar et al. 2009); null: no projection, the weight decay λ bounds Θ.
    actor_projection_radius: float | None = None
    #: B robots in lockstep (ROBOT_UPDATES): each (beyond the paper: their B updates one after
    #: the other, B steps of algorithm 3) | mean (the mean of their updates from the same
    #: parameters: the robots of a turn, env.robots_per_turn, teach as much as one).
    robot_updates: str = "each"
    #: Θ's entries start uniform in ±this (0: at zero). The paper gives no initialisation; the
    #: active-efficient-coding code starts the actor in ±0.4 (its weight_range).
    initial_actor_range: float = 0.0
    #: v's entries start uniform in ±this (0: at zero); the active-efficient-coding code: ±0.05.
    initial_critic_range: float = 0.0
    #: Whether the step into a trial, across the pan's reset to the trial's start, is learnt like
    #: any other within a presentation. The paper does not say; the active-efficient-coding code
    #: does not learn the first step of a trial.
    learn_reset_step: bool = False
    #: Filled by the trainer: seeds the action-sampling generator.
    seed: int = MISSING


def check(check: Checks) -> None:
    actions = check.get("policy.actions")
    if not isinstance(actions, list) or len(set(actions)) < 2:
        check.fail("policy.actions", actions, "needs at least two distinct pan increments")
    largest = float(check.get("env.max_pan_increment_deg"))
    for action in actions:
        if not math.isfinite(action):
            check.fail("policy.actions", actions, "must be finite pan increments in degrees")
        if abs(action) > largest + 1e-9:
            check.fail(
                "policy.actions",
                actions,
                f"{action:g}° is beyond env.max_pan_increment_deg={largest:g}",
            )
    for key in ("critic_lr", "advantage_lr", "actor_lr", "weight_decay", "reward_change_gain"):
        check.number(f"policy.{key}", at_least=0)
    check.number("policy.discount", at_least=0, at_most=1)
    check.number("policy.reward_rate", above=0, at_most=1)
    check.number("policy.temperature", above=0)
    actor_lr, decay = float(check.get("policy.actor_lr")), float(check.get("policy.weight_decay"))
    if actor_lr * decay >= 1:
        check.fail(
            "policy.weight_decay",
            decay,
            f"policy.actor_lr·policy.weight_decay must be below 1 (actor_lr={actor_lr:g})",
        )
    check.choice("policy.feature_norm", FEATURE_NORMS)
    check.choice("policy.robot_updates", ROBOT_UPDATES)
    check.integer("policy.zscore_horizon", 0, " (states; 0: all)")
    check.number("policy.eye_position_reference_m", at_least=0, what=" (metres; 0: off)")
    check.optional_number("policy.actor_projection_radius", above=0, what=" or null")
    check.number("policy.initial_actor_range", at_least=0)
    check.number("policy.initial_critic_range", at_least=0)
