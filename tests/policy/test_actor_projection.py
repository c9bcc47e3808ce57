"""Algorithm 3's projection Γ of the actor parameters (the paper-as-written family's bound on
Θ, in place of our weight decay λ)."""

import pytest

from parallax.policy import NaturalActorCritic
from parallax.tools.analysis.synthetic_pursuit import (
    PursuitTaskConfig,
    SyntheticPursuit,
    train_on_synthetic_pursuit,
)


def _trained_actor_norm(
    radius: float | None, steps: int = 200, robot_updates: str = "each"
) -> float:
    task = SyntheticPursuit(
        num_robots=4, config=PursuitTaskConfig(units_per_scale=24, episode_length=8), seed=3
    )
    policy = NaturalActorCritic(
        task.config.state_dim,
        task.config.num_scales,
        seed=5,
        feature_norm="zscore",
        discount=1.0,
        advantage_lr=0.5,
        actor_lr=0.5,
        weight_decay=0.0,
        eye_position_reference_m=0.0,
        reward_change_gain=0.0,
        actor_projection_radius=radius,
        robot_updates=robot_updates,
    )
    train_on_synthetic_pursuit(policy, task, steps)
    return float(policy.actor.norm())


def test_the_projection_keeps_the_actor_inside_its_ball():
    free = _trained_actor_norm(None)
    assert free > 2.0  # without Γ the actor grows past the ball used below
    assert _trained_actor_norm(2.0) <= 2.0 + 1e-9


def test_a_ball_larger_than_the_actor_changes_nothing():
    assert _trained_actor_norm(1e6, robot_updates="mean") == _trained_actor_norm(
        None, robot_updates="mean"
    )
    # with robot_updates=each, a projected run takes its rows one by one and a free one through
    # the rows' Gram matrices: the same steps, rounded otherwise
    assert _trained_actor_norm(1e6) == pytest.approx(_trained_actor_norm(None), rel=1e-5)
