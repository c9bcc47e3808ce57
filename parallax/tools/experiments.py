"""Which experiment files must be trained, and which are a replay of another.

The distance learner (paper §3.5–3.5.2) never acts on the world, so two experiment files whose
composed configs differ only in the distance learner's settings (``distance.*``, and which pan
of each trial it reads, ``train.distance_readout``) give the same eye movements, and
`parallax-replay` of one's runs with the other's settings gives exactly what training the other
would (tests/tools/test_replay.py). The paper's Tables 4–5 rows with and without weighting, and
the recipe less an improvement on the distance side, are such pairs; `launch/reproduce.sh` trains
one of each and replays the other.

    python -m parallax.tools.experiments recipe_multi_5_20 recipe_multi_5_20_weighted …

prints one line per experiment file, in the order given:

    train recipe_multi_5_20_weighted
    replay recipe_multi_5_20 recipe_multi_5_20_weighted distance.weighting=false

An experiment is replayed from the first one before it that is trained and matches it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass

from hydra.errors import HydraException
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from parallax.config import compose, flatten, result_settings


def replayable(key: str) -> bool:
    """Whether a setting belongs to the distance learner alone (what parallax-replay may change;
    the body's walk aside, which replays only with odometry targets)."""
    return key.startswith("distance.") or key == "train.distance_readout"


@dataclass(frozen=True)
class Plan:
    """One experiment file: trained, or replayed from ``source`` with ``overrides``."""

    name: str
    source: str | None = None
    overrides: tuple[str, ...] = ()

    def line(self) -> str:
        if self.source is None:
            return f"train {self.name}"
        return " ".join(["replay", self.name, self.source, *self.overrides])


def settings(name: str, overrides: Sequence[str] = ()) -> dict:
    """The flattened config of ``experiment=name`` (plus ``overrides``), seed and result-neutral
    settings left out."""
    composed = compose([f"experiment={name}", *overrides])
    return result_settings(flatten(OmegaConf.to_container(composed, resolve=True)))


def override_text(value) -> str:
    """A setting's value as a Hydra override writes it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return "[" + ",".join(override_text(v) for v in value) + "]"
    return str(value)


class ExperimentError(ValueError):
    """An experiment file that does not compose; the message names it."""


def plan(names: Sequence[str]) -> list[Plan]:
    configs = {}
    for name in names:
        try:
            configs[name] = settings(name)
        except (HydraException, OmegaConfBaseException) as exc:
            text = str(exc).strip()
            reason = text.splitlines()[0] if text else type(exc).__name__
            raise ExperimentError(f"experiment={name}: {reason}") from None
    plans: list[Plan] = []
    for name in names:
        mine = configs[name]
        for trained in (p.name for p in plans if p.source is None):
            theirs = configs[trained]
            differ = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
            if all(replayable(k) for k in differ):
                overrides = tuple(f"{k}={override_text(mine.get(k))}" for k in differ)
                plans.append(Plan(name, trained, overrides))
                break
        else:
            plans.append(Plan(name))
    return plans


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.experiments", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("names", nargs="+", metavar="EXPERIMENT", help="conf/experiment/NAME.yaml")
    args = parser.parse_args(argv)
    try:
        plans = plan(args.names)
    except ExperimentError as exc:
        print(f"parallax.tools.experiments: error: {exc}", file=sys.stderr)
        sys.exit(2)
    for p in plans:
        print(p.line())


if __name__ == "__main__":
    main()
