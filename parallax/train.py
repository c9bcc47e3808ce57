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

The run directory is checked before Hydra writes its own record (.hydra/) into it, by
:func:`run_directory_error`: a folder that cannot be created or written, a checkpoint that cannot
be resumed (damaged, not a checkpoint, another run's) or a run trained with other settings end
the command with one line and exit status 2, the folder left as it was. A sweep's job
directories are checked the same way before its first job. A run whose numbers stop being finite
stops with one line and exit status 1 (parallax.health).
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
from parallax.writable import folder_problem

#: Hydra flags after which no run starts, or whose config source `compose` cannot see: Hydra
#: handles these command lines on its own.
_HYDRA_ONLY = ("help", "hydra_help", "cfg", "info", "shell_completion", "config_path")


def _fail(message: str, status: int = 2) -> None:
    print(f"parallax-train: error: {message}", file=sys.stderr)
    sys.exit(status)


class RunRefused(CompactHydraException):
    """A sweep's job that cannot run or stopped: Hydra reports this one line, not a traceback."""


def _usable(path: Path, cfg: DictConfig) -> bool:
    from parallax import checkpoint

    try:
        checkpoint.read(path, config=cfg)
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
            changed = changed_settings(load_run_config(run_dir), cfg)
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
            checkpoint.read(previous, config=cfg)
        except checkpoint.CheckpointError as exc:
            return f"{exc}; move the checkpoints aside to start afresh"
        return None
    if not latest.exists():
        return (
            f"{run_dir} holds {checkpoint.PREVIOUS_NAME} but no {checkpoint.CHECKPOINT_NAME}; "
            "resume from it with train.resume_from=previous, or move it aside to start afresh"
        )
    try:
        checkpoint.read(latest, config=cfg)
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


def check_command_line(argv: Sequence[str]) -> str | None:
    """The one-line error for a command line that cannot run, or None (Hydra takes it from here).

    A single run is composed and validated; a sweep's jobs are composed (each validates itself
    when it runs, so that a bad job fails alone). Then the run directory of each is checked
    (:func:`run_directory_error`), before Hydra writes anything.
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
        return error or run_directory_error(without_hydra(cfg), _output_dir(cfg, False))
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


@hydra.main(config_path=f"pkg://{CONFIG_MODULE}", config_name=CONFIG_NAME, version_base="1.3")
def train(cfg: DictConfig) -> float:
    """Train one run in Hydra's run directory; returns the final eye-movement MAE (for sweepers)."""
    # Hydra logs INFO to the console; the renderer's libraries announce themselves at that level
    # when they are imported (below).
    for noisy in ("absl", "OpenGL"):
        logging.getLogger(noisy).setLevel(logging.WARNING)

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
    # main() asked this before Hydra wrote into the folder; a sweep's job asks it again, as its
    # launcher may run it much later or requeue it
    error = run_directory_error(cfg, run_dir, key="hydra.sweep.dir" if in_sweep else None)
    if error:
        refuse(error)
    from parallax import checkpoint
    from parallax.health import Diverged
    from parallax.trainer import Trainer, format_summary

    # what the terminal gets, the run's train.log gets too (released by Hydra's job callback)
    transcript.keep(run_dir / f"{HydraConfig.get().job.name}.log", f"[{run_dir.name}] " * in_sweep)
    print(f"[parallax] run directory: {run_dir}", flush=True)
    trainer = Trainer(cfg, run_dir)
    try:
        summary = trainer.fit()
    except checkpoint.CheckpointError as exc:  # one that reads but does not fit the models
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
    error = check_command_line(sys.argv[1:])
    if error:
        _fail(error)
    try:
        train()
    finally:
        summary = transcript.sweep_summary()  # a sweep's jobs, each in a line
        if summary:
            print(summary, flush=True)


if __name__ == "__main__":
    main()
