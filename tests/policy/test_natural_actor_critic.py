"""Tests of the pursuit policy (paper §3.4; Bhatnagar et al. 2009, algorithm 3)."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf

from parallax.config import PolicyConfig
from parallax.policy import FEATURE_NORMS, NaturalActorCritic
from parallax.tools.analysis.synthetic_pursuit import (
    PUBLISHED,
    PursuitTaskConfig,
    SyntheticPursuit,
    correcting_fraction,
    train_on_synthetic_pursuit,
)
from parallax.train import check_command_line

# PUBLISHED (imported): the published pursuit step sizes with θ alone as the state, the settings
# these tests check
SMALL_DIM = 12


def _policy(**overrides: object) -> NaturalActorCritic:
    kwargs: dict = dict(state_dim=SMALL_DIM, num_scales=2, temperature=0.7, seed=3, **PUBLISHED)
    kwargs.update(overrides)
    return NaturalActorCritic(**kwargs)


def _randomise(policy: NaturalActorCritic, seed: int) -> None:
    """Non-zero v, w, Θ, J so every term of the equations matters."""
    generator = torch.Generator().manual_seed(seed)
    for buffer in (policy.critic, policy.advantage, policy.actor):
        buffer.copy_(torch.randn(buffer.shape, generator=generator))
    policy.average_reward.fill_(-0.4)


def _states(batch: int, seed: int, dim: int = SMALL_DIM) -> torch.Tensor:
    return torch.rand(batch, dim, generator=torch.Generator().manual_seed(seed)) * 0.5


def _reference_step(
    policy: NaturalActorCritic,
    phi: torch.Tensor,
    action: int,
    reward: float,
    next_phi: torch.Tensor,
) -> dict[str, torch.Tensor]:
    """Algorithm 3 for one transition, written from the equations with ψ from autograd."""
    J = (1 - policy.reward_rate) * policy.average_reward + policy.reward_rate * reward
    v = policy.critic
    delta = reward - J + policy.discount * (v @ next_phi) - v @ phi
    theta = policy.actor.clone().requires_grad_(True)
    log_pi = torch.log_softmax(theta @ phi / policy.temperature, dim=0)[action]
    (psi,) = torch.autograd.grad(log_pi, theta)
    w = policy.advantage
    w_new = w + policy.advantage_lr * (delta * psi - psi * (psi * w).sum())
    return dict(
        critic=v + policy.critic_lr * delta * phi,
        advantage=w_new,
        actor=policy.actor * (1 - policy.actor_lr * policy.weight_decay) + policy.actor_lr * w_new,
        average_reward=J,
    )


def test_compatible_features_are_the_score_of_the_softmax_policy() -> None:
    # With v = 0, w = 0 and α_v = 0 the advantage step is α_n·δ·ψ with δ = r − J, so the
    # update reveals ψ; it must equal ∇_Θ log π(a|φ) of π = softmax(Θφ/T) (autograd).
    policy = _policy(critic_lr=0.0, temperature=0.37)
    policy.actor.copy_(torch.randn(policy.actor.shape, generator=torch.Generator().manual_seed(1)))
    phi = _states(1, seed=2)
    action = 5
    policy.update(
        phi, torch.tensor([action]), torch.tensor([-0.8]), _states(1, seed=4), torch.tensor([True])
    )
    delta = -0.8 - float(policy.average_reward)
    psi = policy.advantage / (policy.advantage_lr * delta)
    theta = (policy.actor.clone() - policy.actor_lr * policy.advantage) / (
        1 - policy.actor_lr * policy.weight_decay
    )
    theta.requires_grad_(True)
    log_pi = torch.log_softmax(theta @ phi[0] / 0.37, dim=0)[action]
    (gradient,) = torch.autograd.grad(log_pi, theta)
    torch.testing.assert_close(psi, gradient, rtol=1e-4, atol=1e-6)
    # The 1/T factor matters: at T = 1 the same formula would differ.
    assert not torch.allclose(psi, gradient * 0.37, rtol=1e-2)


@pytest.mark.parametrize("norm", FEATURE_NORMS)
def test_single_robot_update_is_exactly_algorithm_3(norm: str) -> None:
    policy = _policy(feature_norm=norm, critic_lr=0.3, advantage_lr=0.2, actor_lr=0.1)
    policy.act(_states(16, seed=8))  # gives the z-score statistics something to hold
    _randomise(policy, seed=5)
    phi, next_phi = _states(1, seed=6), _states(1, seed=7)
    expected = _reference_step(
        policy, policy.features(phi)[0], 2, -0.3, policy.features(next_phi)[0]
    )
    policy.update(phi, torch.tensor([2]), torch.tensor([-0.3]), next_phi, torch.tensor([True]))
    for name, value in expected.items():
        torch.testing.assert_close(getattr(policy, name), value.detach(), rtol=1e-5, atol=1e-6)


def test_batched_update_is_the_mean_of_single_robot_updates_over_valid_rows() -> None:
    batched, single = _policy(robot_updates="mean"), _policy()
    for policy in (batched, single):
        _randomise(policy, seed=9)
    phi, next_phi = _states(4, seed=10), _states(4, seed=11)
    action, reward = torch.tensor([0, 6, 3, 1]), torch.tensor([-0.1, -0.9, -0.5, -0.2])
    valid = torch.tensor([True, False, True, True])
    results = []
    for row in torch.nonzero(valid).flatten().tolist():
        trial = _policy()
        trial.load_state_dict(single.state_dict())
        expected = _reference_step(
            trial, phi[row], int(action[row]), float(reward[row]), next_phi[row]
        )
        results.append(expected)
    batched.update(phi, action, reward, next_phi, valid)
    for name in ("critic", "advantage", "actor"):
        mean = torch.stack([r[name].detach() for r in results]).mean(dim=0)
        torch.testing.assert_close(getattr(batched, name), mean, rtol=1e-5, atol=1e-6)
    expected_j = (1 - batched.reward_rate) * -0.4 + batched.reward_rate * float(
        reward[valid].mean()
    )
    assert float(batched.average_reward) == pytest.approx(expected_j, rel=1e-6)


def test_gated_rows_change_nothing() -> None:
    policy = _policy(feature_norm="zscore")
    policy.act(_states(8, seed=12))
    _randomise(policy, seed=13)
    before = {k: v.clone() for k, v in policy.state_dict().items() if torch.is_tensor(v)}
    stats = policy.update(
        _states(3, seed=14),
        torch.tensor([1, 2, 3]),
        torch.tensor([-1.0, -2.0, -3.0]),
        _states(3, seed=15),
        torch.zeros(3, dtype=torch.bool),
    )
    after = policy.state_dict()
    for name, value in before.items():
        assert torch.equal(after[name], value), name
    assert stats["valid_fraction"] == 0.0 and stats["td_error"] == 0.0
    # And a valid row next to gated ones: the same as updating with that row alone.
    alone = _policy(feature_norm="zscore")
    alone.load_state_dict(policy.state_dict())
    phi, next_phi = _states(3, seed=16), _states(3, seed=17)
    action, reward = torch.tensor([4, 0, 6]), torch.tensor([-0.2, -5.0, -7.0])
    policy.update(phi, action, reward, next_phi, torch.tensor([True, False, False]))
    alone.update(phi[:1], action[:1], reward[:1], next_phi[:1], torch.tensor([True]))
    for name, value in alone.state_dict().items():
        if torch.is_tensor(value):
            torch.testing.assert_close(policy.state_dict()[name], value, rtol=0, atol=0)


def _run(policy: NaturalActorCritic, task: SyntheticPursuit, steps: int) -> None:
    train_on_synthetic_pursuit(policy, task, steps)


def _small_task(seed: int) -> SyntheticPursuit:
    config = PursuitTaskConfig(units_per_scale=24, episode_length=8)
    return SyntheticPursuit(num_robots=4, config=config, seed=seed)


def _task_policy(task: SyntheticPursuit, seed: int, norm: str = "zscore") -> NaturalActorCritic:
    return NaturalActorCritic(
        task.config.state_dim,
        task.config.num_scales,
        seed=seed,
        **{**PUBLISHED, "feature_norm": norm},
    )


@pytest.mark.parametrize("norm", FEATURE_NORMS)
def test_same_seed_gives_identical_parameters(norm: str) -> None:
    runs = []
    for _ in range(2):
        task = _small_task(seed=21)
        policy = _task_policy(task, seed=7, norm=norm)
        _run(policy, task, 60)
        runs.append(policy.state_dict())
    for name, value in runs[0].items():
        if torch.is_tensor(value):
            assert torch.equal(runs[1][name], value), name
    other_task = _small_task(seed=21)
    other = _task_policy(other_task, seed=8, norm=norm)
    _run(other, other_task, 60)
    assert not torch.equal(other.actor, runs[0]["actor"])  # the seed does drive sampling


def test_resume_from_state_dict_continues_bit_identically() -> None:
    task = _small_task(seed=30)
    policy = _task_policy(task, seed=4)
    _run(policy, task, 40)
    saved = {k: (v.clone() if torch.is_tensor(v) else v) for k, v in policy.state_dict().items()}
    states = _states(5, seed=31, dim=task.config.state_dim)
    continued = policy.act(states)

    resumed = _task_policy(_small_task(seed=99), seed=123)
    resumed.load_state_dict(saved)
    assert torch.equal(resumed.act(states), continued)
    assert torch.equal(resumed.normalizer.mean, policy.normalizer.mean)
    for name in ("critic", "advantage", "actor", "average_reward", "updates"):
        assert torch.equal(getattr(resumed, name), getattr(policy, name)), name
    assert int(resumed.updates) > 0 and float(resumed.average_reward) != 0.0


def test_greedy_picks_the_mode_and_sampling_follows_the_probabilities() -> None:
    policy = _policy()
    _randomise(policy, seed=40)
    phi = _states(1, seed=41)
    probabilities = policy.probabilities(phi)[0]
    assert int(policy.act(phi, greedy=True)) == int(probabilities.argmax())
    draws = policy.act(phi.expand(20000, -1))
    frequencies = torch.bincount(draws, minlength=policy.num_actions).double() / 20000
    # 4.5 standard errors of a binomial frequency: a wrong sampler fails, a right one does not.
    tolerance = 4.5 * (probabilities.double() * (1 - probabilities.double()) / 20000).sqrt()
    assert bool(((frequencies - probabilities.double()).abs() <= tolerance + 1e-9).all())


def test_untrained_greedy_policy_keeps_the_eye_still() -> None:
    policy = _policy()
    choice = policy.act(_states(3, seed=42), greedy=True)
    assert torch.equal(policy.action_values[choice], torch.zeros(3, dtype=torch.float64))


def test_feature_normalisations() -> None:
    states = _states(50, seed=43) + 0.01
    l1 = _policy(feature_norm="l1_per_scale").features(states)
    torch.testing.assert_close(l1.reshape(50, 2, -1).sum(dim=2), torch.ones(50, 2))

    zscore = _policy(feature_norm="zscore")
    zscore.act(states[:20])
    zscore.act(states[20:])
    zscore.eval()
    zscore.act(states + 1.0)  # eval mode: the statistics must not move
    features = zscore.features(states).double() * math.sqrt(SMALL_DIM)
    torch.testing.assert_close(
        features.mean(dim=0), torch.zeros(SMALL_DIM, dtype=torch.float64), atol=1e-5, rtol=0
    )
    torch.testing.assert_close(
        features.std(dim=0, unbiased=False),
        torch.ones(SMALL_DIM, dtype=torch.float64),
        atol=1e-4,
        rtol=0,
    )


def test_zscore_statistics_forget_beyond_their_horizon() -> None:
    remembering = _policy(feature_norm="zscore")
    forgetting = _policy(feature_norm="zscore", zscore_horizon=200)
    early, late = _states(1000, seed=44), _states(1000, seed=45) + 2.0
    for policy in (remembering, forgetting):
        for chunk in torch.cat([early, late]).split(50):
            policy.act(chunk)
    late_mean = late.double().mean(dim=0)
    # After 1000 late states the forgetting statistics sit on the late mean, the others midway.
    assert float((forgetting.normalizer.mean - late_mean).abs().max()) < 0.05
    assert float((remembering.normalizer.mean - late_mean).abs().min()) > 0.8
    assert float(forgetting.normalizer.count) == 200.0


@pytest.mark.parametrize(
    "seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)]
)
def test_learns_to_correct_a_synthetic_pursuit_offset(seed: int) -> None:
    # Tuned, non-negative, ~0.006 activities with texture and noise; reward −|offset|.
    # The schema's settings (except the run-time sizes), with centred_unit features and without
    # the eye-position and reward-change entries: the synthetic task gives θ alone.
    settings = OmegaConf.to_container(OmegaConf.structured(PolicyConfig))
    config = PursuitTaskConfig(units_per_scale=96)
    task = SyntheticPursuit(num_robots=16, config=config, seed=seed)
    settings.update(
        state_dim=config.state_dim,
        num_scales=config.num_scales,
        seed=seed,
        feature_norm="centred_unit",
        eye_position_reference_m=0.0,
        reward_change_gain=0.0,
    )
    policy = instantiate(settings)
    before = correcting_fraction(policy, task)
    curve = train_on_synthetic_pursuit(policy, task, steps=1500)
    assert before < 0.5  # untrained greedy keeps still, which corrects nothing
    assert curve[-1].correcting >= 0.9


def test_config_instantiates_with_the_interface_keys() -> None:
    settings = OmegaConf.structured(PolicyConfig)
    assert settings["_target_"] == "parallax.policy.NaturalActorCritic"
    for key in ("state_dim", "num_scales", "seed"):
        assert OmegaConf.is_missing(settings, key), key
    parameters = set(inspect.signature(NaturalActorCritic).parameters)
    assert set(settings.keys()) - {"_target_"} == parameters
    settings.state_dim, settings.num_scales, settings.seed = 576, 2, 0
    policy = instantiate(settings)
    assert isinstance(policy, NaturalActorCritic)
    assert policy.action_values.tolist() == [-0.2, -0.1, -0.05, 0.0, 0.05, 0.1, 0.2]


@pytest.mark.parametrize(
    "overrides, message",
    [
        (dict(state_dim=13), "num_scales"),
        (dict(num_scales=0), "num_scales"),
        (dict(actions=[0.1, 0.1, 0.2]), "actions"),
        (dict(seed=-1), "seed"),
    ],
)
def test_what_the_config_check_cannot_see_is_refused(overrides: dict, message: str) -> None:
    # the coder's sizes and the seed are filled in at run time; the config check asks for two
    # distinct actions, not for all of them distinct
    with pytest.raises(ValueError, match=message):
        _policy(**overrides)


#: Bad policy settings the config check refuses (tests/config/test_bad_input.py has the others).
BAD_SETTINGS = [
    "policy.eye_position_reference_m=nan",
    "policy.reward_change_gain=-1",
    "policy.initial_actor_range=-1",
    "policy.initial_critic_range=-1",
    "policy.actor_projection_radius=nan",
]


@pytest.mark.parametrize("override", BAD_SETTINGS)
def test_bad_settings_are_refused_by_the_config_check(override: str) -> None:
    line = check_command_line([override])
    assert line is not None and line.startswith(override.partition("=")[0] + "="), line


def test_bad_inputs_are_refused() -> None:
    policy = _policy()
    phi = _states(2, seed=50)
    good = dict(
        phi=phi,
        action=torch.tensor([0, 1]),
        reward=torch.tensor([-0.1, -0.2]),
        next_phi=phi,
        valid=torch.tensor([True, True]),
    )
    with pytest.raises(ValueError, match="phi"):
        policy.act(phi[:, :5])
    for name, bad in [
        ("action", torch.tensor([0, 7])),
        ("action", torch.tensor([0.0, 1.0])),
        ("valid", torch.tensor([1, 1])),
        ("reward", torch.tensor([-0.1])),
        ("next_phi", torch.full((2, SMALL_DIM), float("nan"))),
    ]:
        with pytest.raises(ValueError, match=name):
            policy.update(**{**good, name: bad})


def test_difference_features_vanish_at_the_reference_and_stay_bounded() -> None:
    # feature_norm=difference (beyond the paper): states are θ(t) − θ_ref, so the zero state is
    # "the view matches I0"; it must give φ = 0, a uniform π and a greedy step of 0.
    policy = _policy(feature_norm="difference")
    differences = _states(40, seed=46) - _states(40, seed=47)
    policy.act(differences)
    policy.eval()  # acting on the probes below must not move the running norm
    mean_norm = float(differences.double().norm(dim=1).mean())
    assert float(policy.normalizer.norm_mean) == pytest.approx(mean_norm, rel=1e-6)
    policy.actor.normal_(generator=torch.Generator().manual_seed(0))
    zero = torch.zeros(2, SMALL_DIM)
    torch.testing.assert_close(policy.features(zero), zero)
    torch.testing.assert_close(policy.probabilities(zero), torch.full((2, 7), 1 / 7))
    assert policy.action_values[policy.act(zero, greedy=True)].tolist() == [0.0, 0.0]
    features = policy.features(torch.cat([differences, 50 * differences]))
    assert float(features.norm(dim=1).max()) <= 1 + 1e-6
    # a difference smaller than the running mean norm is scaled, not stretched to unit length
    small = differences[:1] * 0.01
    torch.testing.assert_close(
        policy.features(small).double(), small.double() / mean_norm, rtol=1e-5, atol=0
    )


def test_eye_position_feature_is_the_implied_nearness_and_bypasses_the_normaliser() -> None:
    # Beyond the paper: ν = tan(pan)·d_ref/l, one entry after the normalised θ.
    policy = _policy(feature_norm="difference", eye_position_reference_m=0.5)
    assert policy.input_dim == SMALL_DIM + 1 and policy.actor.shape == (7, SMALL_DIM + 1)
    lateral, distance = 0.05, 4.0
    on_target = math.degrees(math.atan(lateral / distance))
    pans = torch.tensor([on_target, 0.0, -on_target, 30.0])
    nu = policy.inputs.eye_position_feature(pans, lateral, policy.actor)
    torch.testing.assert_close(
        nu.squeeze(1).double(),
        torch.tensor([0.5 / distance, 0.0, -0.5 / distance, 1.0], dtype=torch.float64),
        rtol=1e-6,
        atol=1e-7,
    )
    assert policy.inputs.eye_position_feature(torch.tensor([3.0]), 0.0, policy.actor).item() == 0.0
    theta = _states(3, seed=60) - _states(3, seed=61)
    states = torch.cat([theta, nu[:3]], dim=1)
    policy.act(states)
    # the running norm sees θ alone, and ν passes through unchanged
    assert float(policy.normalizer.norm_mean) == pytest.approx(
        float(theta.double().norm(dim=1).mean()), rel=1e-6
    )
    features = policy.features(states)
    torch.testing.assert_close(features[:, -1], nu[:3, 0])
    torch.testing.assert_close(features[:, :-1], policy.normalizer(theta))
    with pytest.raises(ValueError, match=f"\\(B, {SMALL_DIM + 1}\\)"):
        policy.act(theta)
    # its weight learns like any other: a rewarded step from a state with ν ≠ 0 moves it
    before = policy.actor[:, -1].clone()
    policy.update(
        states,
        torch.tensor([6, 6, 6]),
        torch.tensor([1.0, 1.0, 1.0]),
        states,
        torch.tensor([True, True, True]),
    )
    policy.update(
        states,
        torch.tensor([6, 6, 6]),
        torch.tensor([1.0, 1.0, 1.0]),
        states,
        torch.tensor([True, True, True]),
    )
    assert not torch.equal(policy.actor[:, -1], before)


def test_reward_change_feature_is_the_signed_relative_change_and_bypasses_the_normaliser() -> None:
    # Beyond the paper: g = clip(gain·(r_t − r_{t−1})/|r_{t−1}|·sign(a_{t−1}), −1, 1), after ν.
    policy = _policy(
        feature_norm="difference", eye_position_reference_m=0.5, reward_change_gain=10.0
    )
    assert policy.input_dim == SMALL_DIM + 2 and policy.actor.shape == (7, SMALL_DIM + 2)
    rewards = torch.tensor([-0.97, -0.97, -0.97, -1.03, -0.5, -0.8])
    previous = torch.tensor([-1.0, -1.0, -1.0, -1.0, -1.0, -0.8])
    increments = torch.tensor([0.1, -0.05, 0.0, 0.2, 0.05, -0.2])
    g = policy.inputs.reward_change_feature(rewards, previous, increments, policy.actor)
    g = g.squeeze(1).double()
    # +3 % after a left step → +0.3; after a right step → −0.3; no step → 0; −3 % after a left
    # step → −0.3; +50 % → clipped to 1; no change → 0
    torch.testing.assert_close(
        g, torch.tensor([0.3, -0.3, 0.0, -0.3, 1.0, 0.0], dtype=torch.float64), rtol=1e-5, atol=1e-6
    )
    assert _policy(reward_change_gain=0.0).input_dim == SMALL_DIM
    theta = _states(3, seed=62) - _states(3, seed=63)
    extra = torch.tensor([[0.1, 0.3], [0.2, -1.0], [0.0, 0.0]])
    states = torch.cat([theta, extra], dim=1)
    policy.act(states)
    assert float(policy.normalizer.norm_mean) == pytest.approx(
        float(theta.double().norm(dim=1).mean()), rel=1e-6
    )
    features = policy.features(states)
    torch.testing.assert_close(features[:, -2:], extra)
    # its weight learns: a rewarded step from states with g ≠ 0 moves the last column
    before = policy.actor[:, -1].clone()
    policy.update(
        states,
        torch.tensor([6, 6, 6]),
        torch.tensor([1.0, 1.0, 1.0]),
        states,
        torch.ones(3, dtype=torch.bool),
    )
    policy.update(
        states,
        torch.tensor([6, 6, 6]),
        torch.tensor([1.0, 1.0, 1.0]),
        states,
        torch.ones(3, dtype=torch.bool),
    )
    assert not torch.equal(policy.actor[:, -1], before)


def test_the_policy_builds_its_state_from_what_the_robots_observe() -> None:
    # θ (minus θ_ref with feature_norm=difference), then ν for the pans, then g for the rewards
    policy = _policy(
        feature_norm="difference", eye_position_reference_m=0.5, reward_change_gain=10.0
    )
    assert policy.uses_reference_state and not _policy().uses_reference_state
    theta, reference = _states(3, seed=64), _states(3, seed=65)
    pans = np.array([1.0, -0.5, 2.0])
    rewards, previous, increments = np.array([-0.9, -1.1, -1.0]), -np.ones(3), np.full(3, 0.1)
    state = policy.state(theta, reference, pans, 0.05, (rewards, previous, increments))
    assert state.shape == (3, policy.input_dim)
    torch.testing.assert_close(state[:, :SMALL_DIM], theta - reference, rtol=0, atol=0)
    inputs, like = policy.inputs, policy.actor
    nu = inputs.eye_position_feature(torch.tensor(pans), 0.05, like)
    torch.testing.assert_close(state[:, SMALL_DIM], nu[:, 0])
    g = inputs.reward_change_feature(rewards, previous, increments, like)
    torch.testing.assert_close(state[:, -1], g[:, 0])
    # no previous step in the trial: the reward-change entry is 0
    assert torch.equal(policy.state(theta, reference, pans, 0.05)[:, -1], torch.zeros(3))
    with pytest.raises(ValueError, match="needs θ_ref"):
        policy.state(theta, None, pans, 0.05)
    with pytest.raises(ValueError, match="takes no θ_ref"):
        _policy().state(theta, reference, pans, 0.05)
    # the paper's state: θ as the coder gives it
    assert _policy().state(theta, None, pans, 0.05) is theta


def test_each_applies_the_rows_updates_one_after_the_other() -> None:
    # robot_updates=each: the batch ends where single-row updates of the valid rows, one
    # after the other, end; the mean of the same rows ends elsewhere.
    each, one_by_one = _policy(robot_updates="each"), _policy()
    mean = _policy(robot_updates="mean")
    for policy in (each, one_by_one, mean):
        _randomise(policy, seed=13)
    phi, next_phi = _states(4, seed=14), _states(4, seed=15)
    action, reward = torch.tensor([2, 5, 0, 6]), torch.tensor([-0.3, -0.8, -0.1, -0.6])
    valid = torch.tensor([True, True, False, True])
    stats = each.update(phi, action, reward, next_phi, valid)
    mean.update(phi, action, reward, next_phi, valid)
    deltas = []
    for row in torch.nonzero(valid).flatten().tolist():
        one = slice(row, row + 1)
        step = one_by_one.update(
            phi[one], action[one], reward[one], next_phi[one], torch.tensor([True])
        )
        deltas.append(step["td_error"])
    for name in ("critic", "advantage", "actor", "average_reward"):
        torch.testing.assert_close(getattr(each, name), getattr(one_by_one, name))
        assert not torch.allclose(getattr(each, name), getattr(mean, name))
    assert stats["td_error"] == pytest.approx(sum(deltas) / len(deltas), rel=1e-6)
    assert int(each.updates) == 3 and int(mean.updates) == 1


def test_each_is_the_mean_for_one_robot() -> None:
    each, mean = _policy(robot_updates="each"), _policy(robot_updates="mean")
    for policy in (each, mean):
        _randomise(policy, seed=16)
    transition = (_states(1, seed=17), torch.tensor([4]), torch.tensor([-0.5]), _states(1, 18))
    for policy in (each, mean):
        policy.update(*transition, torch.tensor([True]))
    for name, value in mean.state_dict().items():
        if isinstance(value, torch.Tensor):
            assert torch.equal(each.state_dict()[name], value), name


def test_each_projects_every_rows_step_when_a_radius_is_set() -> None:
    each = _policy(actor_projection_radius=0.5, robot_updates="each")
    one_by_one = _policy(actor_projection_radius=0.5)
    for policy in (each, one_by_one):
        _randomise(policy, seed=24)
    phi, next_phi = _states(3, seed=25), _states(3, seed=26)
    action, reward = torch.tensor([1, 4, 6]), torch.tensor([-0.2, -0.7, -0.4])
    each.update(phi, action, reward, next_phi, torch.ones(3, dtype=torch.bool))
    for row in range(3):
        one = slice(row, row + 1)
        one_by_one.update(phi[one], action[one], reward[one], next_phi[one], torch.tensor([True]))
    assert float(each.actor.norm()) <= 0.5 + 1e-6
    for name in ("critic", "advantage", "actor", "average_reward"):
        assert torch.equal(getattr(each, name), getattr(one_by_one, name)), name


def test_initial_ranges_start_the_weights_as_the_active_efficient_coding_code() -> None:
    """Θ and v uniform in ±range (AEC's weight_range), the same for the same seed, and drawn
    apart from the sampling stream: the actions drawn for given logits do not change."""
    plain = _policy(seed=5)
    assert not plain.actor.any() and not plain.critic.any()
    started = _policy(seed=5, initial_actor_range=0.4, initial_critic_range=0.05)
    assert 0 < float(started.actor.abs().max()) <= 0.4
    assert float(started.actor.abs().max()) > 0.3  # spread over the range, not clustered
    assert 0 < float(started.critic.abs().max()) <= 0.05
    again = _policy(seed=5, initial_actor_range=0.4, initial_critic_range=0.05)
    assert torch.equal(again.actor, started.actor) and torch.equal(again.critic, started.critic)
    other = _policy(seed=6, initial_actor_range=0.4, initial_critic_range=0.05)
    assert not torch.equal(other.actor, started.actor)
    assert torch.equal(plain._generator.get_state(), started._generator.get_state())


def test_the_critics_scale_is_reported() -> None:
    """mean |v·φ| and ‖v‖ with the critic the update leaves."""
    policy = _policy()
    _randomise(policy, seed=2)
    phi, next_phi = _states(3, seed=1), _states(3, seed=2)
    before = float((policy.features(phi) @ policy.critic).abs().mean())
    stats = policy.update(
        phi, torch.tensor([0, 1, 2]), torch.full((3,), -0.5), next_phi, torch.ones(3, dtype=bool)
    )
    after = float((policy.features(phi) @ policy.critic).abs().mean())
    assert after != pytest.approx(before, rel=1e-3)
    assert stats["critic_scale"] == pytest.approx(after, rel=1e-6)
    assert stats["critic_norm"] == pytest.approx(float(policy.critic.norm()), rel=1e-6)


@pytest.mark.parametrize("feature_norm", ["none", "difference", "zscore"])
@pytest.mark.parametrize("robot_updates", ["each", "mean"])
def test_rows_all_valid_update_exactly_as_the_same_rows_beside_a_gated_one(
    feature_norm, robot_updates
) -> None:
    """Every row valid (the loop's case, which skips the masks) gives the bits of the same rows
    picked out of a batch with a gated row, statistics included."""
    plain, masked = (_policy(feature_norm=feature_norm, robot_updates=robot_updates) for _ in "ab")
    for policy in (plain, masked):
        policy.act(_states(5, seed=20))
        _randomise(policy, seed=21)
    phi, next_phi = _states(4, seed=22), _states(4, seed=23)
    action, reward = torch.tensor([1, 5, 0, 2]), torch.tensor([-0.3, -0.6, -0.2, -8.0])
    stats = plain.update(phi[:3], action[:3], reward[:3], next_phi[:3], torch.ones(3, dtype=bool))
    gated = torch.tensor([True, True, True, False])
    masked_stats = masked.update(phi, action, reward, next_phi, gated)
    for name, value in plain.state_dict().items():
        if torch.is_tensor(value):
            assert torch.equal(masked.state_dict()[name], value), name
    for key in ("td_error", "average_reward", "critic_norm", "advantage_norm", "actor_norm"):
        assert stats[key] == masked_stats[key], key
