"""Checkpoints that resume exactly: every state dict, counters and RNG states, written atomically.

A checkpoint is written at a presentation boundary, where the world holds no state but its
random generator (the next reset draws the next stimulus), so restoring it continues the same
sequence of numbers. Writing goes to a temporary file in the same directory, then `os.replace`,
so a kill at any moment leaves either the old or the new checkpoint, never half of one. The
trainer keeps the checkpoint before the latest one too (``checkpoint_previous.pt``): a file can
still be damaged after it was written (a full disk, an interrupted copy), and a run whose latest
checkpoint is damaged resumes from the one before (``train.resume_from=previous``).

:func:`read` is the one way in: a file that is not a whole checkpoint of this run, or one whose
tensors hold numbers that are not finite, raises :class:`CheckpointError`, whose message names the
file and what is wrong with it, before anything is loaded into a model.
"""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import signal
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np
import torch

CHECKPOINT_NAME = "checkpoint.pt"
#: The checkpoint written before the latest one (the trainer keeps it; see the module docstring).
PREVIOUS_NAME = "checkpoint_previous.pt"
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


def save_atomic(
    state: dict[str, Any], path: str | Path, previous: str | Path | None = None
) -> None:
    """Write ``state`` to ``path`` atomically; with ``previous``, the file ``path`` held until
    now becomes ``previous`` first (atomically too), so that at every moment ``path`` is a whole
    checkpoint and ``previous`` the one before it (or, between the two renames, the same)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _signals_deferred():
        fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as f:
                torch.save(state, f)
                f.flush()
                os.fsync(f.fileno())
            if previous is not None and path.exists():
                _keep_as(path, Path(previous))
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


def _keep_as(path: Path, previous: Path) -> None:
    """``previous`` becomes the file at ``path``: a hard link (no copy), or a copy on file
    systems without links, put in place by a rename."""
    fd, tmp = tempfile.mkstemp(prefix=previous.name + ".", suffix=".tmp", dir=previous.parent)
    os.close(fd)
    try:
        os.unlink(tmp)  # os.link needs a free name; mkstemp only reserved a unique one
        try:
            os.link(path, tmp)
        except OSError:
            shutil.copyfile(path, tmp)
        os.replace(tmp, previous)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    # weights_only=False: the checkpoint holds numpy RNG states and plain Python containers
    # that we wrote ourselves.
    return torch.load(Path(path), map_location=map_location, weights_only=False)


#: What every checkpoint of parallax-train holds at its top level.
REQUIRED_KEYS = (
    "presentation",
    "steps",
    "wall_time",
    "experiment",
    "eye",
    "dist",
    "before_perturbation",
    "last_distance_stats",
    "global_rng",
)
#: The first bytes of a zip archive, torch.save's format.
_ZIP_MAGIC = b"PK\x03\x04"


def describe(exc: BaseException) -> str:
    """``Type: first sentence`` of an error from torch or pickle (torch's run on for lines)."""
    text = str(exc).strip()
    return (
        f"{type(exc).__name__}: {text.splitlines()[0].split('. ')[0]}"
        if text
        else type(exc).__name__
    )


class CheckpointError(ValueError):
    """A checkpoint that cannot be used: ``<path> <what is wrong>``. The commands add what to do."""

    def __init__(self, path: str | Path, problem: str):
        super().__init__(f"{path} {problem}")
        self.path, self.problem = Path(path), problem

    def __reduce__(self):
        return (type(self), (self.path, self.problem))


def non_finite(state: Any, where: str = "") -> str | None:
    """The first tensor or array of ``state`` (through dicts, lists and tuples) holding numbers
    that are not finite, in words (``experiment.policy.critic: 3 of 288 NaN``), or None. Plain
    floats are left alone: a statistic that is NaN by definition (a loss before its first fit)
    is one."""
    if isinstance(state, dict):
        items = state.items()
    elif isinstance(state, (list, tuple)):
        items = ((f"[{i}]", item) for i, item in enumerate(state))
    else:
        items = ()
    for key, item in items:
        at = f"{where}{key}" if str(key).startswith("[") else f"{where}.{key}".lstrip(".")
        found = non_finite(item, at)
        if found:
            return found
    if isinstance(state, torch.Tensor) and (state.is_floating_point() or state.is_complex()):
        values = state.detach().cpu()
        nan, inf = int(torch.isnan(values).sum()), int(torch.isinf(values).sum())
    elif isinstance(state, np.ndarray) and state.dtype.kind in "fc":
        nan, inf = int(np.isnan(state).sum()), int(np.isinf(state).sum())
    else:
        return None
    if not nan and not inf:
        return None
    kinds = " and ".join(
        f"{count} {name}" for count, name in ((nan, "NaN"), (inf, "infinite")) if count
    )
    return f"{where}: {kinds} of {state.size if isinstance(state, np.ndarray) else state.numel()}"


def read(
    path: str | Path,
    config: Any = None,
    map_location: str | torch.device = "cpu",
    finite: bool = True,
) -> dict[str, Any]:
    """The checkpoint at ``path``, checked: a whole torch file holding a dict with every key of
    :data:`REQUIRED_KEYS` and, when it records the settings it was trained with and ``config``
    (a composed config) is given, written with the same ones (the changes a resume may make
    aside); and tensors and arrays of finite numbers only. The trainer writes no checkpoint
    while its numbers are not finite, so one that holds them was damaged, but in a study of
    divergence (``train.stop_after_non_finite=null``), whose checkpoints may hold what diverged:
    a checkpoint that records that setting, or any with ``finite=False`` (a command continuing
    such a study), is not checked for them. Anything else raises :class:`CheckpointError`. The
    recorded settings come back in this parallax's words
    (:func:`parallax.config.upgrade_saved`)."""
    from omegaconf import OmegaConf

    from parallax.config import changed_settings, upgrade_saved

    path = Path(path)
    try:
        size = path.stat().st_size
        with path.open("rb") as f:
            head = f.read(len(_ZIP_MAGIC))
    except OSError as exc:
        raise CheckpointError(path, f"cannot be read ({exc.strerror or exc})") from None
    if size == 0:
        raise CheckpointError(path, "is empty")
    try:
        state = load(path, map_location=map_location)
    except Exception as exc:  # pickle and torch's zip reader raise many kinds for a broken file
        kind = "is truncated or damaged" if head == _ZIP_MAGIC else "is not a torch checkpoint"
        raise CheckpointError(path, f"{kind} ({size} bytes; {describe(exc)})") from None
    if not isinstance(state, dict):
        raise CheckpointError(
            path, f"is not a checkpoint of parallax-train (it holds a {type(state).__name__})"
        )
    missing = [key for key in REQUIRED_KEYS if key not in state]
    if missing:
        raise CheckpointError(
            path, f"lacks {', '.join(missing)} (not a checkpoint of parallax-train)"
        )
    if isinstance(state.get("config"), dict):
        state["config"] = upgrade_saved(state["config"])
    if config is not None and isinstance(state.get("config"), dict):
        # a schedule point not yet reached may move (parallax.config.changed_settings)
        reached = state["presentation"] if isinstance(state["presentation"], int) else None
        saved = OmegaConf.create(state["config"])
        changed = changed_settings(saved, config, reached=reached)
        if changed:
            listed = "; ".join(changed[:2]) + ("; …" if len(changed) > 2 else "")
            raise CheckpointError(path, f"was written by a run with other settings ({listed})")
    found = non_finite(state) if finite and not _studies_divergence(state) else None
    if found:
        raise CheckpointError(path, f"holds numbers that are not finite ({found})")
    return state


def _studies_divergence(state: dict[str, Any]) -> bool:
    """Whether the checkpoint's run ran on through numbers that were not finite."""
    recorded = state.get("config")
    train = recorded.get("train") if isinstance(recorded, dict) else None
    return isinstance(train, dict) and train.get("stop_after_non_finite", 0) is None


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
