"""The paper's readout (§3.2, eq. 16): q_p is the pan at the trial's last iteration."""

from __future__ import annotations

import numpy as np

from parallax.readouts.base import PanReadout


class LastPan(PanReadout):
    """The pan at the trial's last iteration."""

    name = "last"
    key = "pans"  # q_p itself: the record's eye-movement vectors
    paper = True

    @staticmethod
    def read(pans: np.ndarray, rewards: np.ndarray) -> np.ndarray:
        return pans[..., -1]
