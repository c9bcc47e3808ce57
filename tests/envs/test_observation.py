"""The typed observation (parallax.envs.observation): the fields of the task's observation spec,
read from a dm_env observation with their values."""

from __future__ import annotations

import numpy as np

import parallax.envs
from parallax.envs.observation import Observation


def test_the_observation_has_the_specs_fields_and_values():
    env = parallax.envs.load(seed=0, lateral_positions=[0.05], image_size=32, stimuli={"count": 2})
    try:
        assert Observation.names() == tuple(env.observation_spec())
        env.reset()
        raw = env.step(0.1).observation
        seen = Observation.of(raw)
        for name in Observation.names():
            value = getattr(seen, name)
            if isinstance(value, np.ndarray):
                assert value is raw[name]  # the images are not copied
            else:
                assert value == raw[name] and type(value) in (int, float)
        assert seen.iteration == 1 and seen.pan == float(raw["pan"])
    finally:
        env.close()
