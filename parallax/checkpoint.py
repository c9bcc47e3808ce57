"""Checkpoints that resume exactly: every state dict, counters and RNG states, written atomically.

A checkpoint is written at a presentation boundary, where the world holds no state but its
random generator (the next reset draws the next stimulus), so restoring it continues the same
sequence of numbers. Writing goes to a temporary file in the same directory, then `os.replace`,
so a kill at any moment leaves either the old or the new checkpoint, never half of one.
"""

from __future__ import annotations

import contextlib
import os
import random
import signal
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np
import torch

CHECKPOINT_NAME = "checkpoint.pt"
#: Written once, when the §5 perturbation is switched on: the state learnt before it.
BEFORE_PERTURBATION_NAME = "checkpoint_before_perturbation.pt"


#: Signals a scheduler sends to stop or preempt a job (SLURM: USR2 before a requeue, TERM).
_DEFERRED_SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGUSR1, signal.SIGUSR2}


@contextlib.contextmanager
def _signals_deferred():
    """Hold stop/preempt signals until the block ends, then deliver them.

    A handler that runs in the middle of torch.save (submitit's requeue handler, a Ctrl-C) tears
    the zip writer and fails the job. Masking the thread is not enough — another thread (the
    TensorBoard writer's) would take the signal and Python would still run the handler at once —
    so the Python-level handlers are swapped for recorders and the signals raised again after.
    Handlers can only be set from the main thread; elsewhere the write is not protected.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    previous = {}
    for signum in _DEFERRED_SIGNALS:
        handler = signal.getsignal(signum)
        if handler is not None:  # None: installed outside Python, cannot be put back
            previous[signum] = handler
            signal.signal(signum, lambda received, frame: pending.append(received))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for signum in pending:
            signal.raise_signal(signum)


def save_atomic(state: dict[str, Any], path: str | Path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _signals_deferred():
        fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as f:
                torch.save(state, f)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


def load(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    # weights_only=False: the checkpoint holds numpy RNG states and plain Python containers
    # that we wrote ourselves.
    return torch.load(Path(path), map_location=map_location, weights_only=False)


def global_rng_state() -> dict[str, Any]:
    """Global generators, saved too in case a library draws from them behind our back."""
    return {
        "python": random.getstate(),
        "numpy": np.random.get_state(),
        "torch": torch.get_rng_state(),
    }


def set_global_rng_state(state: dict[str, Any]) -> None:
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])
    torch.set_rng_state(state["torch"].cpu())  # map_location=cuda moves it too
