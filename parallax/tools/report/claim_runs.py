"""The runs and measures behind the claims report (`python -m parallax.tools.report.claims`): which
committed runs stand for a set-up of the paper, the measure each claim reads from them, and how
two set-ups are paired.

A set-up is a folder below the records root (docs/results/runs), an experiment file and,
where the folder holds several, the settings that single it out (``coder.scales`` of the scale
ablation). Each family (the paper's algorithm, ``paper_*``, and ours, ``recipe_*``) has its own
runs of every set-up. The measures are the paper's:

- the eye: the last-100-trial mean eye error at each lateral position (Tables 2–3);
- the distance: the frozen model's error on held-out photographs, distance by distance
  (parallax-eval; Tables 4–5), or the trainer's online error (the only distance error the
  single-position runs have: their learner keeps no model to evaluate);
- the time to learn a position: the first presentation whose recent eye error there is within a
  threshold (parallax.tools.analysis.time_to_learn), before §5's perturbation.

Pairing: two set-ups are compared on the seeds both have, and within a seed on the keys both
measures have (lateral positions; distances of the grid). parallax-eval draws its held-out
photographs from the run's ``env.stimuli`` settings alone (the photograph of the i-th distance
is the i-th of the held-out split, whatever the seed), so two evaluations with the same texture
settings and grid saw the same photograph at each distance: they pair photograph by photograph.
:func:`held_out` keys each error by its distance and those settings, so that evaluations on
other textures share no key and are never paired.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from parallax.distance.metrics import RANGES
from parallax.tools.analysis.time_to_learn import first_learnt, recent_mae_per_position
from parallax.tools.replay import REPLAYABLE_PREFIXES as DISTANCE_ONLY_PREFIXES
from parallax.tools.report.runs import ReportError, Run, find_run_dirs, load_run

#: Where the reproduction keeps its runs (launch/reproduce.sh's RECORD_ROOT).
RECORDS = Path("docs/results/runs")
#: The families compared, by their key in the report and their experiment files' prefix.
FAMILIES = {"paper_family": "paper", "ours": "recipe"}
#: The experiment whose coder the scale ablation changes, per family (launch/ablation_scales.sh).
SCALE_ABLATION = {"paper": "paper_multi_5_10", "recipe": "recipe_multi_5_20_weighted"}

Measure = Callable[[Run], "dict[str, float] | None"]


@dataclass(frozen=True)
class Setup:
    """One set-up's runs in a family: ``{family}`` in folder and experiment is the family's prefix,
    ``{scale_ablation}`` its experiment of the scale ablation."""

    folder: str
    experiment: str | None = None  # None: every run of the folder (a replay's)
    settings: tuple[tuple[str, Any], ...] = ()  # flat setting → value, to single out runs
    overrides: tuple[str, ...] = ()  # the Hydra overrides that give those settings
    script: str | None = None  # the launch script that makes the runs, if one does

    def folder_of(self, prefix: str) -> str:
        return self.folder.format(family=prefix)

    def experiment_of(self, prefix: str) -> str | None:
        if self.experiment is None:
            return None
        return self.experiment.format(family=prefix, scale_ablation=SCALE_ABLATION[prefix])


def experiment_name(run: Run) -> str | None:
    """The run's ``experiment=`` override (a replay has none)."""
    for override in run.overrides:
        if override.startswith("experiment="):
            return override.split("=", 1)[1]
    return None


def _same(value: Any, wanted: Any) -> bool:
    if isinstance(value, (list, tuple)) and isinstance(wanted, (list, tuple)):
        return list(value) == list(wanted)
    return value == wanted


class Records:
    """The finished runs below the records root, read once per folder."""

    def __init__(self, root: str | Path = RECORDS):
        self.root = Path(root)
        self._folders: dict[str, list[Run]] = {}

    def folder(self, name: str) -> list[Run]:
        if name not in self._folders:
            path = self.root / name
            runs = [load_run(d) for d in find_run_dirs(path)] if path.is_dir() else []
            self._folders[name] = [r for r in runs if r.summary is not None]
        return self._folders[name]

    @staticmethod
    def _only_its_overrides(run: Run, setup: Setup, eye_only: bool) -> bool:
        """Whether the run was launched with nothing beyond its experiment, its seed and the
        set-up's own settings; for a measure of the eye (``eye_only``), settings of the distance
        learner aside, as they never change the eye (parallax-replay)."""
        allowed = {key for key, _ in setup.settings} | {o.split("=", 1)[0] for o in setup.overrides}
        keys = {o.split("=", 1)[0].lstrip("+") for o in run.overrides}
        if eye_only:
            keys = {k for k in keys if not k.startswith(DISTANCE_ONLY_PREFIXES)}
        return keys - {"experiment", "seed"} <= allowed

    def runs(self, setup: Setup, prefix: str, eye_only: bool = False) -> dict[int, Run]:
        """The set-up's finished runs by seed; empty when there are none (not yet trained).
        ``eye_only``: for a measure that reads the eye alone."""
        experiment = setup.experiment_of(prefix)
        found: dict[int, Run] = {}
        for run in self.folder(setup.folder_of(prefix)):
            if experiment is not None and experiment_name(run) != experiment:
                continue
            if experiment is not None and not self._only_its_overrides(run, setup, eye_only):
                continue  # the experiment with other settings: not what its command gives
            flat = run.flat
            if not all(_same(flat.get(key), value) for key, value in setup.settings):
                continue
            seed = int(run.seed)
            if seed in found:
                raise ReportError(
                    f"{run.path} and {found[seed].path}: two runs of {experiment or 'one replay'} "
                    f"with seed {seed}"
                )
            found[seed] = run
        return found


# --- measures: {key: value} of one run, the keys being what two runs pair on ----------------------


def eye(phase: str, positions: Sequence[str] | None = None) -> Measure:
    """Last-100-trial mean eye error (deg) per lateral position (of ``positions`` if given)."""

    def read(run: Run) -> dict[str, float] | None:
        trials = run.last_trials(phase)
        if not trials:
            return None
        keep = run.lateral_labels if positions is None else positions
        return {p: float(trials[p]["mean"]) for p in keep if p in trials} or None

    return read


def eye_mean(phase: str) -> Measure:
    """The run's eye error averaged over its lateral positions, as one value."""

    def read(run: Run) -> dict[str, float] | None:
        per_position = eye(phase)(run)
        return None if not per_position else {"mean": float(np.mean(list(per_position.values())))}

    return read


#: The evaluations a distance measure reads: (parallax-eval's --split, the result's key). Held
#: out: the frozen greedy eye on held-out photographs; as trained: the learning policy's draws on
#: the training photographs (the paper's probable scoring of Tables 4–5).
EVALUATIONS = {"held_out": ("heldout", "distance"), "as_trained": ("train", "distance_sampled")}


def held_out(phase: str, distance_range: str | None = None) -> Measure:
    """Held-out error (%) per grid distance of the phase's evaluation (one photograph each), in
    ``distance_range`` (a key of Tables 4–5's ranges) if given."""
    return evaluated_error(phase, distance_range, "held_out")


def as_trained(phase: str, distance_range: str | None = None) -> Measure:
    """The same for the eye as trained (parallax-eval --split train)."""
    return evaluated_error(phase, distance_range, "as_trained")


def evaluated_error(phase: str, distance_range: str | None, scoring: str) -> Measure:
    """Error (%) per grid distance of the phase's evaluation of the kind ``scoring`` (a key of
    EVALUATIONS), one photograph each, in ``distance_range`` if given."""
    split, key = EVALUATIONS[scoring]

    def read(run: Run) -> dict[str, float] | None:
        found = run.eval_for(phase, split=split)
        distance = (found or {}).get(key) or {}
        if not distance.get("per_distance"):
            return None
        if int(found.get("textures_per_distance", 1)) != 1:
            raise ReportError(
                f"{found.get('_path')}: {found['textures_per_distance']} photographs per distance; "
                "the claims pair one photograph per distance"
            )
        textures = ",".join(f"{k}={v}" for k, v in sorted((found.get("stimuli") or {}).items()))
        low, high, included = RANGES.get(distance_range, (-math.inf, math.inf, True))
        return {
            f"{float(d):.2f} m on {textures}": float(error)
            for d, error in distance["per_distance"].items()
            if low <= float(d) and (float(d) <= high if included else float(d) < high)
        } or None

    read.reads_distance = True
    read.split = split
    return read


def online(phase: str) -> Measure:
    """The trainer's online distance error (%, total over its window), as one value."""

    def read(run: Run) -> dict[str, float] | None:
        total = (run.online_distance(phase) or {}).get("total")
        return None if total is None or not math.isfinite(float(total)) else {"total": total}

    read.reads_distance = True
    return read


def time_to_learn(
    positions: Sequence[str], trials: int, threshold: float = 0.2, label: str = "presentation"
) -> Measure:
    """The first presentation before the perturbation whose recent eye error (over ``trials``
    trials) is within ``threshold`` at each of ``positions``, averaged over them, as one value; a
    position never within it counts as the presentation after the last (censored)."""

    def read(run: Run) -> dict[str, float] | None:
        rows = _recent_mae(str(run.path), trials)
        if not rows or not all(p in rows[0]["mae"] for p in positions):
            return None
        robots = int(run.config["env"]["robots"])
        times = []
        for position in positions:
            row = first_learnt(rows, robots, trials, threshold, [position])
            times.append(len(rows) + 1 if row is None else int(row["presentation"]))
        return {label: float(np.mean(times))}

    return read


@functools.cache
def _recent_mae(path: str, trials: int) -> list[dict]:
    # read once per run: the two sides of a comparison read other positions of the same run
    return recent_mae_per_position(path, trials)


@dataclass(frozen=True)
class Side:
    """One side of a comparison: a measure of its set-ups' runs, per seed and key the mean over
    the set-ups, or (``best``) the set-up with the lowest mean over seeds and keys."""

    label: str
    setups: tuple[Setup, ...]
    measure: Measure
    evaluated: str | None = None  # the phase whose parallax-eval the measure reads
    best: bool = False

    def values(
        self, records: Records, prefix: str
    ) -> tuple[dict[int, dict[str, float]], list[Run], str | None]:
        """{seed: {key: value}} over the seeds every set-up has a value for, the runs read, and
        (``best``) the experiment chosen."""
        eye_only = not getattr(self.measure, "reads_distance", False)
        per_setup = [records.runs(setup, prefix, eye_only) for setup in self.setups]
        runs = [run for found in per_setup for run in found.values()]
        if self.best:
            measured = [_measured([found], self.measure) for found in per_setup]
            means = [
                np.mean([np.mean(list(v.values())) for v in m.values()]) if m else np.inf
                for m in measured
            ]
            if not np.isfinite(min(means, default=np.inf)):
                return {}, runs, None
            chosen = int(np.argmin(means))
            return measured[chosen], runs, self.setups[chosen].experiment_of(prefix)
        return _measured(per_setup, self.measure), runs, None


def _measured(per_setup: list[dict[int, Run]], measure: Measure) -> dict[int, dict[str, float]]:
    seeds = set.intersection(*(set(found) for found in per_setup)) if per_setup else set()
    out = {}
    for seed in sorted(seeds):
        measured = [measure(found[seed]) for found in per_setup]
        if any(m is None for m in measured):
            continue
        keys = set.intersection(*(set(m) for m in measured))
        out[seed] = {k: float(np.mean([m[k] for m in measured])) for k in sorted(keys)}
    return out


def pairs(
    a: dict[int, dict[str, float]], b: dict[int, dict[str, float]]
) -> tuple[list[int], list[list[float]], list[list[float]]]:
    """The seeds both sides have, and each seed's values on the keys both have."""
    seeds = [s for s in sorted(a) if s in b and set(a[s]) & set(b[s])]
    keys = {s: sorted(set(a[s]) & set(b[s])) for s in seeds}
    return (
        seeds,
        [[a[s][k] for k in keys[s]] for s in seeds],
        [[b[s][k] for k in keys[s]] for s in seeds],
    )
