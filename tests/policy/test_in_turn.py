"""The policy's "each" mode through the rows' Gram matrices (parallax.policy.in_turn) against the
one update path of algorithm 3 applied row by row."""

from __future__ import annotations

import pytest
import torch

from parallax.policy.in_turn import apply_in_turn
from tests.policy.test_natural_actor_critic import _policy, _randomise, _states


@pytest.mark.parametrize("overrides", [{}, dict(critic_lr=1.0, advantage_lr=0.1, actor_lr=0.1)])
def test_in_turn_through_gram_matrices_is_the_row_by_row_loop(overrides: dict) -> None:
    # 16 rows: what each row sees of the earlier rows' steps is carried through ΦΦᵀ and ΦΦ′ᵀ
    fast, loop = _policy(**overrides), _policy(**overrides)
    for policy in (fast, loop):
        _randomise(policy, seed=19)
    phi, next_phi = _states(16, seed=20), _states(16, seed=21)
    action = torch.randint(0, 7, (16,), generator=torch.Generator().manual_seed(22))
    reward = -torch.rand(16, generator=torch.Generator().manual_seed(23))
    rows = (fast.features(phi), action, reward, fast.features(next_phi))
    deltas = apply_in_turn(fast, *rows)
    torch.testing.assert_close(deltas, loop._step_each(*rows), rtol=1e-4, atol=1e-5)
    for name in ("critic", "advantage", "actor", "average_reward"):
        torch.testing.assert_close(getattr(fast, name), getattr(loop, name), rtol=1e-4, atol=1e-5)
    assert int(fast.updates) == int(loop.updates) == 16


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_a_step_that_is_not_finite_is_left_to_the_row_by_row_loop() -> None:
    policy = _policy()
    _randomise(policy, seed=24)
    before = {k: v.clone() for k, v in policy.state_dict().items() if torch.is_tensor(v)}
    phi = _states(4, seed=25) * 1e30  # the steps overflow float32
    rows = (phi, torch.tensor([0, 1, 2, 3]), -torch.ones(4), phi)
    assert apply_in_turn(policy, *rows) is None
    for name, value in before.items():
        assert torch.equal(policy.state_dict()[name], value), name
