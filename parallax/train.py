"""`parallax-train`: the Hydra application that runs the paper's whole loop (Fig. 1).

    parallax-train                                   # our recipe (parallax/config/schema.py)
    parallax-train experiment=paper_multi_5_20       # the paper's algorithm as written
    parallax-train curriculum=multi_5_10 distance.y=2 coder.scales=[coarse]
    parallax-train -m seed=0,1,2 hydra/launcher=joblib

A bad command line fails before Hydra creates a run directory, with one line naming the key and
the value and exit status 2: the overrides are composed (Hydra checks the types against the
schema) and validated (:func:`parallax.config.validate`) first, and only then does Hydra take
over. In a sweep (-m) every job's overrides are composed first, so that a typo stops the sweep
before any job runs; each job then validates its own configuration and a bad job fails alone,
before the trainer writes anything into its directory.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

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
from parallax.config.overrides import composition_error, parse_error

#: Hydra flags after which no run starts, or whose config source `compose` cannot see: Hydra
#: handles these command lines on its own.
_HYDRA_ONLY = ("help", "hydra_help", "cfg", "info", "shell_completion", "config_path")


def _fail(message: str) -> None:
    print(f"parallax-train: error: {message}", file=sys.stderr)
    sys.exit(2)


def _sweep_jobs(overrides: list[str]) -> list[list[str]] | None:
    """Each job's overrides, as Hydra's basic sweeper will run them (None for other sweepers)."""
    if any(o.lstrip("+~").startswith("hydra/sweeper=") for o in overrides):
        return None
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_overrides(overrides)
    return [job for batch in BasicSweeper.split_arguments(parsed, None) for job in batch]


def check_command_line(argv: Sequence[str]) -> str | None:
    """The one-line error for a command line that cannot run, or None (Hydra takes it from here).

    A single run is composed and validated; a sweep's jobs are composed (each validates itself
    when it runs, so that a bad job fails alone).
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
    if error or not args.multirun:
        return error or composition_error(overrides, check=True)
    jobs = _sweep_jobs(overrides)
    for job in jobs or []:
        error = composition_error(list(job), check=False)
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

    def refuse(key: str, value: object, reason: str) -> None:
        if in_sweep:
            raise ConfigError(key, value, reason)
        _fail(str(ConfigError(key, value, reason)))

    try:
        validate(cfg)  # before the trainer exists: nothing but Hydra's .hydra/ is written yet
    except ConfigError as exc:
        refuse(exc.key, exc.value, exc.reason)
    from parallax.trainer import Trainer, format_summary

    run_dir = HydraConfig.get().runtime.output_dir
    print(f"[parallax] run directory: {run_dir}", flush=True)
    trainer = Trainer(cfg, run_dir)
    if trainer.checkpoint_path.exists() and not cfg.resume:
        trainer.exp.close()
        refuse(
            "resume",
            False,
            f"{trainer.checkpoint_path} exists; resume=true continues that run, or choose "
            "another directory with hydra.run.dir=...",
        )
    if trainer.summary_path.exists() and not trainer.checkpoint_path.exists():
        # a finished run kept as a record without its checkpoint (docs/results/runs): training
        # again from the start would overwrite the record's metrics
        trainer.exp.close()
        refuse(
            "hydra.run.dir",
            str(trainer.run_dir),
            "holds a finished run (summary.json) without its checkpoint; choose another "
            "directory with hydra.run.dir=...",
        )
    if trainer.checkpoint_path.exists() and (trainer.run_dir / RUN_CONFIG_NAME).is_file():
        # Run directories are named by the overrides only: a run trained with another default
        # would otherwise be continued with this one.
        try:
            changed = changed_settings(load_run_config(trainer.run_dir), cfg)
        except ValueError as exc:
            changed = [str(exc)]
        if changed:
            trainer.exp.close()
            refuse(
                "resume",
                True,
                f"cannot resume {trainer.run_dir}, it was trained with other settings "
                f"({'; '.join(changed[:3])}{'; …' if len(changed) > 3 else ''}); pass them to "
                "continue it, or choose another directory with hydra.run.dir=...",
            )
    try:
        summary = trainer.fit()
    finally:
        trainer.exp.close()
    print(format_summary(summary), flush=True)
    return float(summary["mae"])


def main() -> None:
    register_resolvers()
    error = check_command_line(sys.argv[1:])
    if error:
        _fail(error)
    train()


if __name__ == "__main__":
    main()
