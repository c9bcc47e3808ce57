"""Beyond the paper: q_p is the pan of the trial's iteration whose image the coder encoded best.

The reward −(eC + eF) (eq. 6) peaks where the two eyes' images match best, at the target pan α*;
the pan there is a readout of s that a runaway at the trial's end does not spoil.
"""

from __future__ import annotations

import numpy as np

from parallax.readouts.base import PanReadout


class BestReward(PanReadout):
    """The pan where the coder's reward was highest in the trial (ties: the earliest; a reward
    that is not a number counts as the lowest)."""

    name = "best_reward"
    key = "best_pans"

    @staticmethod
    def read(pans: np.ndarray, rewards: np.ndarray) -> np.ndarray:
        best = np.argmax(np.where(np.isnan(rewards), -np.inf, rewards), axis=-1)
        return np.take_along_axis(pans, best[..., None], axis=-1)[..., 0]
