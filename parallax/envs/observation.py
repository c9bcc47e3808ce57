"""What the robot observes at one iteration (paper §3.2, Fig. 3), as a typed record.

The dm_control task (:mod:`parallax.envs.task`) hands dm_env an ``OrderedDict`` of arrays, as
its ``observation_spec`` says; the loop and its executors read an :class:`Observation`, made once
per step from that dict by :meth:`Observation.of`. Its fields are the spec's names, in its order.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np


@dataclass(frozen=True)
class Observation:
    """One robot's observation after a reset or a step."""

    reference: np.ndarray  # I0, (H, W, 3) uint8: the left eye at l0 with pan 0, read-only
    image: np.ndarray  # I(t), (H, W, 3) uint8: the left eye now
    pan: float  # α (deg)
    target_pan: float  # α*, the pan that fixates the panel's centre (deg)
    distance: float  # d, the panel's distance (m)
    lateral_position: float  # the body's offset: l_p, or x(t) in a continuous sweep (m)
    position_index: int  # p, the trial's place in the episode
    iteration: int  # t, the iteration's place in its trial (0 … t_h − 1)
    texture_index: int  # the panel's photograph

    @classmethod
    def of(cls, observation: Mapping[str, np.ndarray]) -> Observation:
        """The record of a dm_env observation dict (``env.step(a).observation``)."""
        return cls(
            reference=observation["reference"],
            image=observation["image"],
            pan=float(observation["pan"]),
            target_pan=float(observation["target_pan"]),
            distance=float(observation["distance"]),
            lateral_position=float(observation["lateral_position"]),
            position_index=int(observation["position_index"]),
            iteration=int(observation["iteration"]),
            texture_index=int(observation["texture_index"]),
        )

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The fields, in the observation spec's order."""
        return tuple(field.name for field in fields(cls))
