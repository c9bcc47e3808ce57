"""The pan readout's interface: which pan of a trial becomes its component q_p of s (§3.5).

The paper reads the pan at a trial's last iteration (eq. 16's q_p); other readouts read another
pan of the same trial. A readout sees the whole trial, each iteration's pan and the coder's
reward −(eC + eF) there (eq. 6), and answers one pan per trial.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np


class PanReadout(ABC):
    """One way of reading a trial's pans; a subclass in a file of this package is found by its
    ``name`` (the value of train.distance_readout)."""

    #: The value of train.distance_readout that chooses it.
    name: ClassVar[str]
    #: The key of metrics.jsonl (and of parallax-eval's samples) that holds its pans, so that
    #: parallax-replay can build s from them.
    key: ClassVar[str]
    #: Whether it is the paper's readout (listed first).
    paper: ClassVar[bool] = False

    @staticmethod
    @abstractmethod
    def read(pans: np.ndarray, rewards: np.ndarray) -> np.ndarray:
        """(…, t_h) pans (deg) and the coder's rewards at each iteration of each trial (NaN:
        not encoded) → (…) the pan each trial reads out."""
