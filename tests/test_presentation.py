"""What one presentation reports (parallax.presentation.Tally → Presentation), fed hand-made
frames (tests/scripted.py): q_p and α* at a trial's last iteration, the start and best pans, the
coder's means, a chosen route's record, and the record before any frame. The continuous sweep's
reading of q_p is tests/envs/test_continuous_motion.py's."""

from __future__ import annotations

import numpy as np
import pytest

from parallax.presentation import Tally
from parallax.readouts.best_reward import BestReward
from tests.scripted import IMAGE, frames

LATERAL = [0.05, 0.1]
TRIAL = 3


def _trial(tally: Tally, p: int, pans: list[list[float]], rewards: list[list[float]]) -> None:
    """A trial at position ``p``: the robots' pans and rewards at each iteration."""
    tally.visit(p)
    for iteration, (pan, reward) in enumerate(zip(pans, rewards, strict=True)):
        tally.seen(frames(iteration, pan, reward, lateral=LATERAL[p]))


def test_q_p_is_the_pan_at_each_trials_last_iteration_and_the_start_pan_at_its_first():
    tally = Tally(2, LATERAL, TRIAL)
    _trial(tally, 0, [[0.0, 0.1], [0.2, 0.3], [0.4, 0.5]], [[-3, -3], [-2, -1], [-1, -2]])
    _trial(tally, 1, [[1.0, 1.1], [1.2, 1.3], [1.4, 1.5]], [[-1, -1], [-1, -2], [-1, -3]])
    pres = tally.presentation(keep_view=False)
    np.testing.assert_array_equal(pres.pans, [[0.4, 1.4], [0.5, 1.5]])
    np.testing.assert_array_equal(pres.start_pans, [[0.0, 1.0], [0.1, 1.1]])
    np.testing.assert_array_equal(pres.targets, np.ones((2, 2)))  # scripted α*
    # the best-coded image's pan; a tie keeps the earlier pan
    np.testing.assert_array_equal(pres.read(BestReward), [[0.4, 1.0], [0.3, 1.1]])
    assert pres.steps == 2 * TRIAL and pres.route is None
    assert pres.reward == pytest.approx(np.mean([-3, -3, -2, -1, -1, -2, -1, -1, -1, -2, -1, -3]))
    assert pres.distances.tolist() == [5.0, 5.0] and pres.textures.tolist() == [0, 0]


def test_turns_fill_their_own_robots():
    tally = Tally(3, LATERAL[:1], 1)
    tally.visit(0)
    tally.seen(frames(0, [0.1, 0.2], [-1, -1], turn=0))
    tally.seen(frames(0, [0.3], [-1], turn=1, first_robot=2))
    assert tally.presentation(keep_view=False).pans[:, 0].tolist() == [0.1, 0.2, 0.3]


def test_a_chosen_route_records_its_positions_and_nan_elsewhere():
    tally = Tally(1, [0.05, 0.1, 0.15], TRIAL, routed=True)
    before = tally.so_far()  # asked before the first trial: nothing seen yet
    assert np.isnan(before.pans).all() and before.route == []
    assert np.isnan(before.distances).all() and before.textures.tolist() == [-1]
    _trial(tally, 1, [[0.0], [0.1], [0.2]], [[-1], [-1], [-1]])
    pres = tally.so_far()
    assert pres.route == [1] and pres.pans[0, 1] == 0.2
    assert np.isnan(pres.pans[0, [0, 2]]).all() and np.isnan(pres.read(BestReward)[0, [0, 2]]).all()


def test_the_record_keeps_the_view_and_the_policys_statistics_when_asked():
    tally = Tally(1, LATERAL[:1], 1)
    _trial(tally, 0, [[0.0]], [[-1]])
    assert tally.presentation(keep_view=False).last_view is None
    pres = tally.presentation(keep_view=True, policy_stats={"td_error": 0.5})
    assert pres.last_view.shape == (IMAGE.shape[0], 2 * IMAGE.shape[1], 3)  # I0 beside I(t)
    assert pres.policy_stats == {"td_error": 0.5}
