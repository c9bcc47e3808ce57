"""Shared test fixtures: the real configs, shrunk so a whole run takes seconds."""

from __future__ import annotations

import os

import pytest
import torch

os.environ.setdefault("MUJOCO_GL", "egl")

#: Overrides that shrink the default experiment: small images and windows, two lateral
#: positions, short trials, a tiny queue. Everything else is the shipped configuration.
TINY = [
    "env.image_size=64",
    "env.trial_length=4",
    "env.stimuli.count=6",
    "coder.scale_specs.coarse.window=64",
    "coder.scale_specs.coarse.subsample=4",
    "coder.scale_specs.fine.window=40",
    "coder.atoms=32",
    "curriculum.lateral_positions=[0.05,0.1]",
    "distance.queue_size=3",
    "distance.hidden=4",
    "train.presentations=6",
    "train.checkpoint_every=2",
    # TensorBoard's pictures and the watched presentation's panel cost a second a tiny run:
    # the tests of them ask for them (IMAGES)
    "train.image_every=1000",
    "metrics.mae_window=20",
]


#: The pictures every third presentation, for the tests of TensorBoard's images and panel.
IMAGES = "train.image_every=3"


@pytest.fixture
def tiny_overrides() -> list[str]:
    return list(TINY)


def train_tiny_run(run_dir, extra_overrides=()):
    """Trains the shrunken default experiment (plus ``extra_overrides``) into ``run_dir``."""
    from parallax.config import compose
    from parallax.trainer import Trainer

    trainer = Trainer(compose(TINY + list(extra_overrides)), run_dir)
    try:
        trainer.fit()
    finally:
        trainer.exp.close()
    return run_dir


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """The suite's tensors are small: a second intra-op thread only adds synchronisation, and on
    a busy shared 2-core machine two OpenMP workers spend their time waiting for each other. The
    trainer does the same by default (train.threads=1)."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)
