"""`parallax-train`: the Hydra application that runs the paper's whole loop (Fig. 1).

    parallax-train                                   # our recipe (parallax/config/schema.py)
    parallax-train experiment=paper_multi_5_20       # the paper's algorithm
    parallax-train curriculum=multi_5_10 distance.y=2 coder.scales=[coarse]
    parallax-train -m seed=0,1,2 hydra/launcher=joblib

A bad command line fails before Hydra creates a run directory, with one line naming the key and
the value and exit status 2: the overrides are composed (Hydra checks the types against the
schema) and validated (:func:`parallax.config.validate`) first, and only then does Hydra take
over. In a sweep (-m) every job's overrides are composed first, so that a typo stops the sweep
before any job runs; each job then validates its own configuration and a bad job fails alone,
before the trainer writes anything into its directory.

A run directory has one writer. A single run takes the folder's lock
(:class:`parallax.run_folder.RunLock`) before Hydra writes its own record (.hydra/) into it, and
then checks the folder, by :func:`run_directory_error`: a folder another process is writing, a
folder that cannot be created or written, a checkpoint that cannot be resumed (damaged, not a
checkpoint, another run's, holding numbers that are not finite) or a run trained with other
settings end the command with one line and exit status 2, the folder left byte for byte as it
was. A checkpoint about to be resumed is also loaded into the run's models then, so that one
that does not fit them is refused before Hydra writes too; the trainer built for that check is
the one that trains. A sweep's job directories are checked the same way (their locks looked at,
not taken) before its first job; each job takes its own folder's lock when it starts, and a job
whose folder was taken meanwhile fails alone. A run whose numbers stop being finite stops with
one line and exit status 1 (parallax.health).
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import CompactHydraException
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

from parallax import transcript
from parallax.config import (
    CONFIG_MODULE,
    CONFIG_NAME,
    RUN_CONFIG_NAME,
    ConfigError,
    changed_settings,
    load_run_config,
    register_resolvers,
    validate,
)
from parallax.config.overrides import composed, parse_error
from parallax.config.plumbing import without_hydra
from parallax.run_folder import RunLock, RunLocked, holder
from parallax.writable import folder_problem

#: Hydra flags after which no run starts, or whose config source `compose` cannot see: Hydra
#: handles these command lines on its own.
_HYDRA_ONLY = ("help", "hydra_help", "cfg", "info", "shell_completion", "config_path")


def _fail(message: str, status: int = 2) -> None:
    print(f"parallax-train: error: {message}", file=sys.stderr)
    sys.exit(status)


class RunRefused(CompactHydraException):
    """A sweep's job that cannot run or stopped: Hydra reports this one line, not a traceback."""


#: The lock this process holds on its run directory (a single run: taken by :func:`main` before
#: Hydra starts), and the trainer built to check the checkpoint it resumes (:func:`_prepare`).
_held: RunLock | None = None
_prepared = None


def _holds(run_dir: Path) -> bool:
    return _held is not None and _held.fd is not None and _held.folder == run_dir.absolute()


def _locked_line(error: RunLocked, key: str) -> str:
    return f"{error}; wait for it to end, or choose another folder with {key}=..."


def _finite_only(cfg: DictConfig) -> bool:
    """Whether a checkpoint this run resumes must hold finite numbers: always, but in a study of
    divergence (train.stop_after_non_finite=null), whose checkpoints may hold what diverged."""
    return cfg.train.stop_after_non_finite is not None


def _usable(path: Path, cfg: DictConfig) -> bool:
    from parallax import checkpoint

    try:
        checkpoint.read(path, config=cfg, finite=_finite_only(cfg))
    except checkpoint.CheckpointError:
        return False
    return True


def run_directory_error(cfg: DictConfig, run_dir: str | Path, key: str | None = None) -> str | None:
    """The one line saying why ``cfg`` cannot run in ``run_dir``, or None. It only reads (a
    temporary probe aside, :mod:`parallax.writable`), so that it can be asked before Hydra writes
    anything into the folder. ``key``: the setting that chose the folder (hydra.run.dir, or
    hydra.sweep.dir for a sweep's job)."""
    from parallax import checkpoint  # torch: only for a command line that gets this far

    run_dir, key = Path(run_dir), key or "hydra.run.dir"
    problem = folder_problem(run_dir)
    if problem:
        reason = f"{problem}; choose another folder with {key}=..."
        return str(ConfigError(key, str(run_dir), reason))
    held = None if _holds(run_dir) else holder(run_dir)
    if held is not None:
        return _locked_line(RunLocked(run_dir.absolute(), held), key)
    latest, previous = run_dir / checkpoint.CHECKPOINT_NAME, run_dir / checkpoint.PREVIOUS_NAME
    present = [path for path in (latest, previous) if path.exists()]
    if present and not cfg.resume:
        reason = (
            f"{present[0]} exists; resume=true continues that run, or choose another directory "
            f"with {key}=..."
        )
        return str(ConfigError("resume", False, reason))
    if (run_dir / "summary.json").exists() and not present:
        # a finished run kept as a record without its checkpoint (docs/results/runs): training
        # again from the start would overwrite the record's metrics
        reason = (
            "holds a finished run (summary.json) without its checkpoint; choose another "
            f"directory with {key}=..."
        )
        return str(ConfigError(key, str(run_dir), reason))
    if not present:
        return None
    if (run_dir / RUN_CONFIG_NAME).is_file():
        # Run directories are named by the overrides only: a run trained with another default
        # would otherwise be continued with this one.
        try:
            # the schedule points are checked below, against the checkpoint's presentation
            changed = changed_settings(load_run_config(run_dir), cfg, schedule=False)
        except ValueError as exc:
            changed = [str(exc)]
        if changed:
            reason = (
                f"cannot resume {run_dir}, it was trained with other settings "
                f"({'; '.join(changed[:3])}{'; …' if len(changed) > 3 else ''}); pass them to "
                f"continue it, or choose another directory with {key}=..."
            )
            return str(ConfigError("resume", True, reason))
    if str(cfg.train.resume_from) == "previous":
        if not previous.exists():
            reason = f"{run_dir} has no {checkpoint.PREVIOUS_NAME} to resume from"
            return str(ConfigError("train.resume_from", "previous", reason))
        try:
            checkpoint.read(previous, config=cfg, finite=_finite_only(cfg))
        except checkpoint.CheckpointError as exc:
            return f"{exc}; move the checkpoints aside to start afresh"
        return None
    if not latest.exists():
        return (
            f"{run_dir} holds {checkpoint.PREVIOUS_NAME} but no {checkpoint.CHECKPOINT_NAME}; "
            "resume from it with train.resume_from=previous, or move it aside to start afresh"
        )
    try:
        checkpoint.read(latest, config=cfg, finite=_finite_only(cfg))
    except checkpoint.CheckpointError as exc:
        if previous.exists() and _usable(previous, cfg):
            return (
                f"{exc}; resume from the one before with train.resume_from=previous, or move "
                "the checkpoints aside to start afresh"
            )
        return f"{exc}; move it aside to start afresh"
    return None


def _sweep_jobs(overrides: list[str]) -> list[list[str]] | None:
    """Each job's overrides, as Hydra's basic sweeper will run them (None for other sweepers)."""
    if any(o.lstrip("+~").startswith("hydra/sweeper=") for o in overrides):
        return None
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_overrides(overrides)
    return [job for batch in BasicSweeper.split_arguments(parsed, None) for job in batch]


def _output_dir(cfg: DictConfig, multirun: bool, job: int = 0) -> Path:
    """The folder Hydra will run a job of ``cfg`` (composed with Hydra's node) in: hydra.run.dir,
    or hydra.sweep.dir/hydra.sweep.subdir for the ``job``-th job of a sweep, as Hydra resolves
    them (relative to the working directory)."""
    with read_write(cfg), open_dict(cfg):
        cfg.hydra.job.num, cfg.hydra.job.id = job, str(job)
    HydraConfig.instance().set_config(cfg)  # for the ${hydra:...} interpolations
    if not multirun:
        return Path(str(OmegaConf.select(cfg, "hydra.run.dir"))).absolute()
    sweep = Path(str(OmegaConf.select(cfg, "hydra.sweep.dir")))
    return (sweep / str(OmegaConf.select(cfg, "hydra.sweep.subdir"))).absolute()


def check_command_line(argv: Sequence[str], hold: bool = False) -> str | None:
    """The one-line error for a command line that cannot run, or None (Hydra takes it from here).

    A single run is composed and validated; a sweep's jobs are composed (each validates itself
    when it runs, so that a bad job fails alone). Then the run directory of each is checked
    (:func:`run_directory_error`), before Hydra writes anything. With ``hold`` (parallax-train
    itself), a single run's folder is locked first and stays locked for the run (:data:`_held`),
    and a checkpoint it resumes is loaded into its models (:func:`_prepare`); a refusal gives
    the lock back and leaves the folder as it was.
    """
    from hydra._internal.utils import get_args_parser

    try:
        args = get_args_parser().parse_args(list(argv))
    except SystemExit:  # a flag Hydra does not know: Hydra says so itself
        return None
    if any(getattr(args, flag, None) for flag in _HYDRA_ONLY) or args.experimental_rerun:
        return None
    overrides = list(args.overrides)
    if args.config_dir:
        if any(o.lstrip("+~").startswith("hydra.searchpath") for o in overrides):
            return None  # the search path is the user's: leave the composition to Hydra
        overrides.append(f"hydra.searchpath=[file://{args.config_dir}]")
    if args.config_name not in (None, CONFIG_NAME):
        return None
    error = parse_error(overrides)
    if error:
        return error
    if not args.multirun:
        cfg, error = composed(overrides, check=True, with_hydra=True)
        if error:
            return error
        task, run_dir = without_hydra(cfg), _output_dir(cfg, False)
        if not hold:
            return run_directory_error(task, run_dir)
        return _hold(task, run_dir)
    jobs = _sweep_jobs(overrides)
    for job, job_overrides in enumerate(jobs or []):
        cfg, error = composed(list(job_overrides), check=False, with_hydra=True)
        if error:
            return error
        task, where = without_hydra(cfg), _output_dir(cfg, True, job)
        error = run_directory_error(task, where, key="hydra.sweep.dir")
        if error:
            return error
    return None


def _hold(cfg: DictConfig, run_dir: Path, key: str = "hydra.run.dir") -> str | None:
    """Lock ``run_dir`` for this process, check it and, for a resume, load its checkpoint into
    the run's models; the error line (the lock given back, the folder as it was) or None."""
    global _held
    problem = folder_problem(run_dir)  # a folder the lock cannot be made in is named as such
    if problem:
        return run_directory_error(cfg, run_dir, key)
    lock = RunLock(run_dir, program="parallax-train")
    try:
        lock.acquire()
    except RunLocked as exc:
        return _locked_line(exc, key)
    _held = lock
    try:
        error = run_directory_error(cfg, run_dir, key) or _prepare(cfg, run_dir)
    except BaseException:
        _held = None
        lock.release(restore=True)
        raise
    if error:
        _held = None
        lock.release(restore=True)
    return error


def _prepare(cfg: DictConfig, run_dir: Path) -> str | None:
    """For a run that resumes, its trainer, built and loaded from the checkpoint (kept in
    :data:`_prepared` for :func:`train`); the error line for a checkpoint that does not fit the
    models, or None. Nothing is written."""
    global _prepared
    from parallax import checkpoint
    from parallax.trainer import Trainer

    latest = str(cfg.train.resume_from) == "latest"
    name = checkpoint.CHECKPOINT_NAME if latest else checkpoint.PREVIOUS_NAME
    if not cfg.resume or not (run_dir / name).exists():
        return None
    _quiet_libraries()
    trainer = Trainer(cfg, run_dir)
    try:
        trainer.load_checkpoint()
    except checkpoint.CheckpointError as exc:
        trainer.exp.close()
        previous = run_dir / checkpoint.PREVIOUS_NAME
        if latest and previous.exists() and _usable(previous, cfg):
            return (
                f"{exc}; resume from the one before with train.resume_from=previous, or move "
                "the checkpoints aside to start afresh"
            )
        return f"{exc}; move it aside to start afresh"
    _prepared = trainer
    return None


def _quiet_libraries() -> None:
    # Hydra logs INFO to the console; the renderer's libraries announce themselves at that level
    # when they are imported (by the trainer).
    for noisy in ("absl", "OpenGL"):
        logging.getLogger(noisy).setLevel(logging.WARNING)


def _trainer_for(cfg: DictConfig, run_dir: Path):
    """The trainer :func:`_prepare` built for this run, if it was built with this very config;
    else a new one."""
    global _prepared
    from parallax.trainer import Trainer

    prepared, _prepared = _prepared, None
    if prepared is not None:
        same = OmegaConf.to_container(prepared.cfg, resolve=True) == OmegaConf.to_container(
            cfg, resolve=True
        )
        if same and prepared.run_dir == run_dir:
            return prepared
        prepared.exp.close()
    return Trainer(cfg, run_dir)


@hydra.main(config_path=f"pkg://{CONFIG_MODULE}", config_name=CONFIG_NAME, version_base="1.3")
def train(cfg: DictConfig) -> float:
    """Train one run in Hydra's run directory; returns the final eye-movement MAE (for sweepers)."""
    _quiet_libraries()

    # In a sweep a bad job must fail alone: exiting would take the launcher's worker (and with
    # joblib every other job) down with it, so raise (Hydra reports the one line: ConfigError is
    # a compact Hydra exception) and let Hydra record the failure.
    in_sweep = HydraConfig.get().mode == RunMode.MULTIRUN

    def refuse(line: str, status: int = 2) -> None:
        if in_sweep:
            raise RunRefused(line)
        _fail(line, status)

    try:
        validate(cfg)  # before the trainer exists: nothing but Hydra's .hydra/ is written yet
    except ConfigError as exc:
        if in_sweep:
            raise
        _fail(str(exc))
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    lock = None
    if not _holds(run_dir):
        # a sweep's job (or a caller other than main()): main() checked the folder before the
        # sweep; the job takes its lock and asks again, as its launcher may run it much later
        # or requeue it
        lock = RunLock(run_dir, program="parallax-train")
        key = "hydra.sweep.dir" if in_sweep else "hydra.run.dir"
        try:
            lock.acquire()
        except RunLocked as exc:
            refuse(_locked_line(exc, key))
        error = run_directory_error(cfg, run_dir, key=key)
        if error:
            lock.release(restore=True)
            refuse(error)
    try:
        return _train(cfg, run_dir, refuse, in_sweep)
    finally:
        if lock is not None:
            lock.release()


def _train(cfg: DictConfig, run_dir: Path, refuse, in_sweep: bool) -> float:
    from parallax import checkpoint
    from parallax.health import Diverged
    from parallax.summary import format_summary

    # what the terminal gets, the run's train.log gets too (released by Hydra's job callback)
    transcript.keep(run_dir / f"{HydraConfig.get().job.name}.log", f"[{run_dir.name}] " * in_sweep)
    print(f"[parallax] run directory: {run_dir}", flush=True)
    trainer = _trainer_for(cfg, run_dir)
    try:
        summary = trainer.fit()
    except checkpoint.CheckpointError as exc:  # a sweep's job: one that does not fit the models
        refuse(f"{exc}; move it aside to start afresh")
    except Diverged as exc:
        refuse(str(exc), status=1)
    finally:
        trainer.exp.close()
    experiment = HydraConfig.get().runtime.choices.get("experiment")
    print(format_summary(summary, experiment), flush=True)
    return float(summary["mae"])


def print_help(argv: Sequence[str]) -> None:
    """`parallax-train [OVERRIDES] --help`: parallax.config.help's text for the composed config
    of these overrides (a bad one: its one line, exit 2)."""
    from parallax.config.help import help_text

    overrides = [a for a in argv if not a.startswith("-")]
    error = parse_error(overrides)
    cfg, error = (None, error) if error else composed(overrides, check=False)
    if error:
        _fail(error)
    print(help_text(cfg, overrides))


def main() -> None:
    register_resolvers()
    if {"--help", "-h"} & set(sys.argv[1:]):  # the settings described, not Hydra's bare tree
        print_help(sys.argv[1:])
        return
    error = check_command_line(sys.argv[1:], hold=True)
    if error:
        _fail(error)
    try:
        train()
    finally:
        if _held is not None:
            _held.release()
        summary = transcript.sweep_summary()  # a sweep's jobs, each in a line
        if summary:
            print(summary, flush=True)


if __name__ == "__main__":
    main()
