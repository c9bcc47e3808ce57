"""`parallax-train`: the Hydra application that runs the paper's whole loop (Fig. 1).

    parallax-train                                   # default experiment (conf/config.yaml)
    parallax-train curriculum=multi_5_10 distance.y=2 coder.scales=[coarse]
    parallax-train -m seed=0,1,2 hydra/launcher=joblib

A bad configuration fails before Hydra creates a run directory: the overrides are composed and
validated first (`parallax.config.validate`), and only then does Hydra take over.
"""

from __future__ import annotations

import logging
import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.types import RunMode
from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from parallax.config import (
    CONFIG_MODULE,
    CONFIG_NAME,
    RUN_CONFIG_NAME,
    ConfigError,
    changed_settings,
    compose,
    load_run_config,
    register_resolvers,
    validate,
)

_SWEEP_MARKERS = (",", "range(", "choice(", "glob(", "interval(")


def _fail(message: str) -> None:
    print(f"parallax-train: error: {message}", file=sys.stderr)
    sys.exit(2)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def prevalidate(argv: list[str]) -> None:
    """Compose and validate a single run's overrides; exit with one line on a bad config.

    Sweeps (-m) and Hydra's own flags are left to Hydra; each job of a sweep validates itself.
    """
    if any(a.startswith("-") for a in argv):
        return
    if any(
        marker in a.split("=", 1)[-1]
        for a in argv
        for marker in _SWEEP_MARKERS
        if not a.split("=", 1)[-1].startswith("[")
    ):
        return
    try:
        validate(compose(argv))
    except ConfigError as exc:
        _fail(str(exc))
    except (HydraException, OmegaConfBaseException) as exc:
        _fail(_first_line(exc))


@hydra.main(config_path=f"pkg://{CONFIG_MODULE}", config_name=CONFIG_NAME, version_base="1.3")
def train(cfg: DictConfig) -> float:
    """Train one run in Hydra's run directory; returns the final eye-movement MAE (for sweepers)."""
    # Hydra logs INFO to the console; the renderer's libraries announce themselves at that level
    # when they are imported (below).
    for noisy in ("absl", "OpenGL"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    from parallax.trainer import Trainer, format_summary

    # In a sweep a bad job must fail alone: exiting would take the launcher's worker (and with
    # joblib every other job) down with it, so raise and let Hydra record the failure.
    in_sweep = HydraConfig.get().mode == RunMode.MULTIRUN
    try:
        validate(cfg)
    except ConfigError as exc:
        if in_sweep:
            raise
        _fail(str(exc))
    run_dir = HydraConfig.get().runtime.output_dir
    print(f"[parallax] run directory: {run_dir}", flush=True)
    trainer = Trainer(cfg, run_dir)
    if trainer.checkpoint_path.exists() and not cfg.resume:
        trainer.exp.close()
        if in_sweep:
            raise ConfigError("resume", f"false but {trainer.checkpoint_path} exists")
        _fail(
            f"resume=false but {trainer.checkpoint_path} exists; resume=true continues that run, "
            "or choose another directory with hydra.run.dir=..."
        )
    if trainer.checkpoint_path.exists() and (trainer.run_dir / RUN_CONFIG_NAME).is_file():
        # Run directories are named by the overrides only, so a default changed in conf/ since
        # the run started would otherwise be resumed into a run trained with the old value.
        changed = changed_settings(load_run_config(trainer.run_dir), cfg)
        if changed:
            trainer.exp.close()
            reason = (
                f"{trainer.run_dir} was trained with other settings ({'; '.join(changed[:3])}"
                f"{'; …' if len(changed) > 3 else ''}); pass them to continue it, or choose "
                "another directory with hydra.run.dir=..."
            )
            if in_sweep:
                raise ConfigError("resume", reason)
            _fail(f"cannot resume: {reason}")
    try:
        summary = trainer.fit()
    finally:
        trainer.exp.close()
    print(format_summary(summary), flush=True)
    return float(summary["mae"])


def main() -> None:
    register_resolvers()
    prevalidate(sys.argv[1:])
    train()


if __name__ == "__main__":
    main()
