"""A training job's lines, kept and named: what `parallax-train` prints also goes to the job's
log (Hydra's ``train.log`` in the run directory, :func:`keep`), and in a sweep (-m) every line
starts with the job's run name, so that jobs running side by side (joblib) can be told apart. At
the end of a sweep, :func:`sweep_summary` names each job's outcome.

The log gets whole lines only: a progress bar's redraws (carriage returns) stay on the terminal,
and the trainer writes its progress line there as well (parallax.run_log).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, TextIO

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

#: The folder of the sweep in progress in this process, set when Hydra starts it.
_sweep: dict[str, Path] = {}


class _Tee:
    """A stream that writes to ``stream`` (each line after ``prefix``) and to ``log``."""

    def __init__(self, stream: TextIO, log: TextIO, prefix: str) -> None:
        self.stream, self.log, self.prefix = stream, log, prefix
        self.line_start, self.redrawn = True, False

    def write(self, text: str) -> int:
        if self.prefix:
            pieces = []
            for piece in text.splitlines(keepends=True):
                pieces += [self.prefix, piece] if self.line_start else [piece]
                self.line_start = piece.endswith("\n")
            self.stream.write("".join(pieces))
        else:
            self.stream.write(text)
        # a bar's redraw, and the newline that closes it, are the terminal's alone
        if "\r" in text or (self.redrawn and not text.strip()):
            self.redrawn = True
        else:
            self.redrawn = False
            self.log.write(text)
            self.log.flush()
        return len(text)

    def flush(self) -> None:
        self.stream.flush()
        self.log.flush()

    def isatty(self) -> bool:
        # a sweep's jobs share the terminal: whole lines, no bars
        return not self.prefix and self.stream.isatty()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


#: The streams a transcript replaced, while one is kept (:func:`keep`).
_replaced: list[TextIO] = []


def keep(log_path: str | Path, prefix: str = "") -> None:
    """From now until :func:`release`, stdout and stderr also go to ``log_path`` (appended),
    each line after ``prefix`` on the terminal."""
    release()
    log = open(log_path, "a", encoding="utf-8")  # noqa: SIM115 (closed by release)
    _replaced[:] = [sys.stdout, sys.stderr]
    sys.stdout, sys.stderr = _Tee(sys.stdout, log, prefix), _Tee(sys.stderr, log, prefix)


def release() -> None:
    """The terminal's streams back, the log closed (nothing if no transcript is kept)."""
    if not _replaced:
        return
    tee = sys.stdout
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    sys.stdout, sys.stderr = _replaced
    _replaced.clear()
    if isinstance(tee, _Tee):
        tee.log.close()


class Transcripts(Callback):
    """Hydra callback (conf/config.yaml, hydra.callbacks): a job's transcript ends with the job;
    a sweep's folder is noted for :func:`sweep_summary`, printed once the sweep is over whether
    or not every job succeeded."""

    def on_job_end(self, config: DictConfig, job_return: Any, **kwargs: Any) -> None:
        release()

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        _sweep["dir"] = Path(str(config.hydra.sweep.dir)).absolute()


def sweep_summary() -> str | None:
    """One line per job of the sweep that ran in this process (None if none did): how far it
    got, its eye-movement MAE and distance error, or why it has no summary."""
    folder = _sweep.pop("dir", None)
    if folder is None or not folder.is_dir():
        return None
    from parallax.tools.report.runs import load_run

    jobs = sorted(path for path in folder.iterdir() if (path / ".hydra").is_dir())
    lines, finished = [], 0
    for job in jobs:
        run = load_run(job)
        summary = run.summary if run.problem is None else None
        if summary is None:
            lines.append(f"[sweep]   {job.name}: {run.problem or 'no summary.json'}")
            continue
        finished += 1
        total, mae = (summary.get("distance_error") or {}).get("total"), summary.get("mae")
        lines.append(
            f"[sweep]   {job.name}: {summary.get('presentations')} presentations, MAE "
            + (f"{mae:.3f}°" if mae is not None else "–")
            + ", distance error "
            + (f"{total:.2f} %" if total is not None else "not yet (queue not full)")
        )
    head = f"[sweep] {folder}: {len(jobs)} jobs, {finished} finished, {len(jobs) - finished} not"
    return "\n".join([head, *lines])
