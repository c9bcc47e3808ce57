"""Groups of runs over seeds, and the settings that vary between groups (the ablations).

Runs that differ only by `seed` (and by settings that do not change results) form a group;
every number of the report is a `Stat` over a group's seeds: mean ± sample sd, with n. A
setting that varies between groups is a `Factor`: one ablation table each, with the shipped
default as its baseline (for replays, the setting of the runs they replay: the report's
``ablation_defaults``).
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import OmegaConf

from parallax.config import result_settings, run_settings
from parallax.metrics import position_label
from parallax.tools.report.runs import Run

#: Settings that name an ablation when they vary; listed first, and never folded into another.
PREFERRED_FACTORS = (
    "curriculum.name",
    "curriculum.lateral_positions",
    "coder.scales",
    "distance.y",
    "distance.queue_size",
    "distance.weighting",
    "env.pan_reset",
    "coder.normalisation",
    "policy.feature_norm",
    "perturbation.camera_rotation_deg",
    "perturbation.blur_sigma",
    "train.presentations",
)


# --- numbers over seeds ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Stat:
    """Mean and sample standard deviation of the finite values among a group's seeds."""

    mean: float
    sd: float
    n: int

    @classmethod
    def of(cls, values: Iterable[float | None]) -> Stat:
        finite = [float(v) for v in values if v is not None and math.isfinite(float(v))]
        if not finite:
            return cls(math.nan, math.nan, 0)
        sd = statistics.stdev(finite) if len(finite) >= 2 else math.nan
        return cls(statistics.fmean(finite), sd, len(finite))

    def text(self, digits: int = 2) -> str:
        """'0.21 ± 0.03'; the mean alone for one seed; '—' for none."""
        if self.n == 0:
            return "—"
        body = f"{self.mean:.{digits}f}"
        return body + (f" ± {self.sd:.{digits}f}" if self.n >= 2 else "")

    def as_dict(self) -> dict:
        return {"mean": finite_or_none(self.mean), "sd": finite_or_none(self.sd), "n": self.n}

    @classmethod
    def from_dict(cls, d: dict | None) -> Stat:
        """The inverse of :meth:`as_dict` (None, or an empty dict, for no seeds)."""
        if not d:
            return cls(math.nan, math.nan, 0)
        return cls(*(math.nan if d.get(k) is None else d[k] for k in ("mean", "sd")), d["n"])


def mean_sd(values: Sequence[float], digits: int = 2) -> str:
    """'0.21 ± 0.03' over runs; '± 0.00' for one run, so that columns line up; '—' for none."""
    if not values:
        return "—"
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.fmean(values):.{digits}f} ± {sd:.{digits}f}"


def finite_or_none(value: Any) -> Any:
    return value if not (isinstance(value, float) and not math.isfinite(value)) else None


def json_ready(obj: Any) -> Any:
    """NaN and inf become null (strict JSON); tuples become lists; Paths become strings."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (np.floating, np.integer)):
        obj = obj.item()
    return finite_or_none(obj)


# --- groups over seeds ----------------------------------------------------------------------------


def _group_key(run: Run) -> tuple:
    return tuple(sorted(result_settings(run.flat).items()))


@dataclass(eq=False)  # identity: a group is one set of runs, however alike two may look
class Group:
    """Finished runs whose configurations differ only by the seed."""

    key: tuple
    runs: list[Run]
    gid: str = ""
    label: str = ""
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def flat(self) -> dict[str, Any]:
        return dict(self.key)

    @property
    def n(self) -> int:
        return len(self.runs)

    @property
    def seeds(self) -> list:
        return [r.seed for r in self.runs]

    @property
    def lateral_labels(self) -> list[str]:
        return self.runs[0].lateral_labels

    @property
    def config(self) -> dict:
        return self.runs[0].config

    @property
    def weighting_effective(self) -> bool:
        """Eqs. (10)–(12) change the input only when weighting is on and a position is sensitive."""
        distance = self.config.get("distance") or {}
        if not distance.get("weighting"):
            return False
        from parallax.distance.weighting import sensitive_positions

        lateral = [
            float(l) for l in (self.config.get("curriculum") or {}).get("lateral_positions") or []
        ]
        sensitivity = distance.get("sensitivity") or {}
        return any(sensitive_positions(lateral, **{k: float(v) for k, v in sensitivity.items()}))

    def stat(self, value_of: Callable[[Run], float | None]) -> Stat:
        return Stat.of(value_of(r) for r in self.runs)


def group_runs(runs: Sequence[Run]) -> tuple[list[Group], list[Run]]:
    """Groups of finished runs, and the duplicates left out (same configuration and seed)."""
    groups: dict[tuple, Group] = {}
    duplicates: list[Run] = []
    for run in runs:
        if run.problem is not None:
            continue
        key = _group_key(run)
        group = groups.setdefault(key, Group(key, []))
        if any(r.seed == run.seed for r in group.runs):
            # the same job twice (e.g. the baseline of several ablation sweeps): counting it twice
            # would shrink the sd and inflate n
            duplicates.append(run)
            continue
        group.runs.append(run)
    for group in groups.values():
        group.runs.sort(key=lambda r: _sortable(r.seed))
    return list(groups.values()), duplicates


def _sortable(value: Any) -> tuple:
    """A sort key that orders mixed values (bools, numbers, strings, lists) without errors."""
    if isinstance(value, bool) or value is None:
        return (0, float(bool(value)), "")
    if isinstance(value, (int, float)):
        return (1, float(value), "")
    if isinstance(value, str):
        return (2, 0.0, value)
    return (3, 0.0, repr(value))


# --- what varies: one ablation table per factor ---------------------------------------------------


@dataclass
class Factor:
    """A setting that varies between groups; `also` are settings that vary with it."""

    key: str
    also: list[str]
    baseline: Any = None


def _partition(groups: Sequence[Group], key: str) -> tuple[int, ...]:
    """Each group's value of `key` as the index of the first group with the same value."""
    values = [g.flat.get(key, "<absent>") for g in groups]
    return tuple(values.index(v) for v in values)


def _refines(fine: tuple[int, ...], coarse: tuple[int, ...]) -> bool:
    """True when groups equal under `fine` are always equal under `coarse`."""
    return all(coarse[i] == coarse[fine[i]] for i in range(len(fine)))


def _preference(key: str) -> tuple:
    return (
        PREFERRED_FACTORS.index(key) if key in PREFERRED_FACTORS else len(PREFERRED_FACTORS),
        key,
    )


def default_flat_config() -> dict[str, Any]:
    """The shipped default configuration, flattened (the baseline of each ablation)."""
    from parallax.config import compose

    return run_settings(OmegaConf.to_container(compose([]), resolve=False))


def find_factors(groups: Sequence[Group], defaults: dict[str, Any] | None = None) -> list[Factor]:
    """The settings that vary between groups, one Factor per ablation; `defaults` give baselines."""
    if len(groups) < 2:
        return []
    keys = sorted(set().union(*(g.flat for g in groups)))
    varying = [k for k in keys if len(set(_partition(groups, k))) > 1]
    by_partition: dict[tuple[int, ...], list[str]] = {}
    for key in varying:
        by_partition.setdefault(_partition(groups, key), []).append(key)
    classes = [sorted(ks, key=_preference) for ks in by_partition.values()]
    # A setting that only follows another (e.g. advantage_lr raised together with feature_norm=none)
    # is folded into the finer one rather than given a table of its own.
    merged: list[list[str]] = []
    for ks in sorted(classes, key=lambda ks: -len(set(_partition(groups, ks[0])))):
        if ks[0] not in PREFERRED_FACTORS:
            host = next(
                (
                    m
                    for m in merged
                    if _refines(_partition(groups, m[0]), _partition(groups, ks[0]))
                ),
                None,
            )
            if host is not None:
                host.extend(ks)
                continue
        merged.append(list(ks))
    factors = []
    for ks in sorted(merged, key=lambda ks: _preference(ks[0])):
        values = [g.flat.get(ks[0]) for g in groups]
        default = (defaults or {}).get(ks[0], "<absent>")
        if default in values:
            baseline = default
        else:  # the most common value (ties: the first in sorted order)
            baseline = max(sorted(set(values), key=_sortable), key=values.count)
        factors.append(Factor(ks[0], ks[1:], baseline))
    return factors


def format_value(key: str, value: Any) -> str:
    """A config value as a table cell (a lateral list as '5–20 cm (16)')."""
    if key.endswith("lateral_positions") and isinstance(value, tuple) and value:
        cm = [position_label(float(v)) for v in value]
        return f"{cm[0]} cm" if len(cm) == 1 else f"{cm[0]}–{cm[-1]} cm ({len(cm)})"
    if isinstance(value, tuple):
        return "[" + ", ".join(format_value(key, v) for v in value) + "]"
    if value == "<absent>":
        return "(absent)"
    return str(value)


def label_groups(groups: list[Group], factors: Sequence[Factor]) -> None:
    """Sort groups (by lateral list, then by the varying settings) and name them g01, g02, …"""

    def order(g: Group) -> tuple:
        lateral = [float(l) for l in g.lateral_labels]
        return (len(lateral), lateral, tuple(_sortable(g.flat.get(f.key)) for f in factors))

    groups.sort(key=order)
    for i, g in enumerate(groups, 1):
        g.gid = f"g{i:02d}"
        g.settings = {f.key: g.flat.get(f.key) for f in factors}
        g.label = (
            ", ".join(f"{k}={format_value(k, v)}" for k, v in g.settings.items()) or "all runs"
        )
