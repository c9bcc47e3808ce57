"""The report's figures: the eye-movement MAE during training (eq. 16) in the manner of the
paper's Figs. 7–9, the distance error against distance as in Figs. 10–11, and one bar plot and
MAE overlay per ablation. Drawn by `parallax.tools.plots`.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallax.tools.report.groups import Factor, Group, Stat, format_value
from parallax.tools.report.runs import read_metrics
from parallax.tools.report.selection import PaperSelection
from parallax.tools.report.tables import final_distance


@dataclass
class Curves:
    steps: np.ndarray
    mae_mean: np.ndarray
    mae_sd: np.ndarray
    per_position: dict[str, np.ndarray]
    perturbation_at: float | None


def eye_records(run) -> list[dict]:
    """A run's metrics records with the eye's keys: a replay's eye is its source's
    (``replayed_from``; its compacted record keeps only its distance learner's), up to the
    replay's last presentation. Empty if the run has none; a replay whose source's record is
    missing is an error, not a curve quietly left out."""
    records = read_metrics(run.path)
    if not records or "mae" in records[0]:
        return records
    source = (run.summary or {}).get("replayed_from")
    if not source:
        return []
    eye = read_metrics(Path(source))
    if not eye:
        raise FileNotFoundError(
            f"{run.path}: a replay whose eye is its source's, {source}, which has no metrics record"
        )
    last = records[-1].get("steps", float("inf"))
    return [rec for rec in eye if rec.get("steps", 0) <= last]


def eye_source(run) -> Path:
    """The run whose eye movements ``run`` made or replayed: a replay's source, else itself."""
    return Path((run.summary or {}).get("replayed_from") or run.path).resolve()


def group_eyes(group: Group) -> frozenset[Path]:
    """The runs whose eye movements a group's runs made or replayed: equal for two groups that
    share their eye (one replays the other's runs, or both replay the same runs)."""
    return frozenset(eye_source(r) for r in group.runs)


def replays(group: Group) -> bool:
    """Whether any of a group's runs replays another's eye movements."""
    return any((r.summary or {}).get("replayed_from") for r in group.runs)


def group_curves(group: Group) -> Curves | None:
    """Mean and sd over seeds of the sliding-window MAE, aligned by presentation."""
    records = [rec for rec in (eye_records(r) for r in group.runs) if rec and "mae" in rec[0]]
    if not records:
        return None
    length = min(len(r) for r in records)
    records = [r[:length] for r in records]
    steps = np.mean([[rec["steps"] for rec in r] for r in records], axis=0)
    mae = np.array([[rec["mae"] for rec in r] for r in records], dtype=float)
    sd = mae.std(axis=0, ddof=1) if len(records) >= 2 else np.zeros(length)
    positions = list(records[0][-1].get("mae_per_position", {}))
    per_position = {
        p: np.nanmean(
            np.array(
                [[rec["mae_per_position"].get(p, np.nan) for rec in r] for r in records],
                dtype=float,
            ),
            axis=0,
        )
        for p in positions
    }
    switches = [next((rec["steps"] for rec in r if rec.get("perturbed")), None) for r in records]
    switches = [s for s in switches if s is not None]
    return Curves(
        steps, mae.mean(axis=0), sd, per_position, float(np.mean(switches)) if switches else None
    )


def _per_distance(results: Sequence[dict], key: str) -> tuple[list[float], np.ndarray] | None:
    """Mean over seeds of eval.json's per-distance errors (distances every seed has)."""
    tables = [(r.get(key) or {}).get("per_distance") for r in results]
    if not tables or any(not t for t in tables):
        return None
    common = sorted(set.intersection(*(set(t) for t in tables)), key=float)
    if not common:
        return None
    return [float(d) for d in common], np.array(
        [[t[d] for d in common] for t in tables], dtype=float
    ).mean(axis=0)


class Figures:
    """Writes PNGs into the output folder and remembers their names for the Markdown."""

    def __init__(self, out: Path | None, prefix: str):
        self.out = out
        self.prefix = prefix
        self.written: list[str] = []

    def path(self, name: str) -> Path | None:
        if self.out is None:
            return None
        filename = f"{self.prefix}{name}.png"
        self.written.append(filename)
        return self.out / filename


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.=-]+", "_", text).strip("_")[:60] or "x"


def figure_mae_curves(figures: Figures, group: Group, curves: Curves) -> str | None:
    """Figs. 7–9 for one group: the MAE over training, mean ± sd over seeds, per position thin."""
    from parallax.tools import plots

    path = figures.path(f"mae_{group.gid}")
    if path is None:
        return None
    thin = {f"{p} cm": (curves.steps, v) for p, v in curves.per_position.items()}
    plots.mean_sd_curves(
        {f"all positions (mean ± sd, n={group.n})": (curves.steps, curves.mae_mean, curves.mae_sd)},
        path,
        f"{group.gid}: {group.label}",
        perturbation_at=curves.perturbation_at,
        thin_curves=thin if len(thin) > 1 else None,
    )
    return path.name


def figure_distance(
    figures: Figures, selection: PaperSelection, groups: Sequence[Group], phase: str
) -> str | None:
    """Fig. 10 (before) / Fig. 11 (after): single-position runs as a mean with min/max, the
    others as lines."""
    from parallax.tools import plots

    singles = [g for g in groups if len(g.lateral_labels) == 1]

    def evals(g: Group) -> list[dict] | None:
        found = [r.eval_for(phase) for r in g.runs]
        return found if all(e is not None for e in found) else None

    single_curves = [
        c for c in (_per_distance(evals(g) or [], "distance") for g in singles) if c is not None
    ]
    band = None
    common = sorted(set.intersection(*(set(d) for d, _ in single_curves))) if single_curves else []
    if common:
        stacked = np.array([[dict(zip(d, e))[x] for x in common] for d, e in single_curves])
        band = (
            f"single positions ({len(single_curves)})",
            common,
            stacked.mean(axis=0),
            stacked.min(axis=0),
            stacked.max(axis=0),
        )
    lines, markers = {}, {}
    for name, g in selection.rows.items():
        found = evals(g)
        if not found:
            continue
        grid = _per_distance(found, "distance")
        if grid is not None:
            lines[f"{name} (n={g.n})"] = grid
        between = _per_distance(found, "distance_between_grid")
        if between is not None:
            markers[f"{name}: between grid points"] = between
    if band is None and not lines:
        return None
    path = figures.path(f"distance_{phase}")
    if path is None:
        return None
    title = (
        "Distance estimation error (Fig. 10)"
        if phase == "before"
        else "Distance estimation error after the perturbation (Fig. 11)"
    )
    plots.error_vs_distance_with_band(lines, path, title, band=band, markers=markers)
    return path.name


def figure_ablation(
    figures: Figures, factor: Factor, rows: Sequence[Group], curves: dict[str, Curves | None]
) -> list[str]:
    """One ablation's bar plot (final MAE, total distance error) and its MAE curves overlaid
    (where the settings' eye movements differ: not for replays of the same runs)."""
    from parallax.tools import plots

    names = []
    labels = [format_value(factor.key, g.flat.get(factor.key)) for g in rows]
    mae = [g.stat(lambda r: r.summary.get("mae")) for g in rows]
    distance = []
    for g in rows:
        per_seed, _ = final_distance(g)
        distance.append(Stat.of(v.get("total") for v in per_seed))
    path = figures.path(f"ablation_{_slug(factor.key)}")
    if path is not None:
        plots.ablation_bars(
            labels,
            {
                "final MAE (deg)": ([s.mean for s in mae], [s.sd for s in mae]),
                "distance error, total (%)": ([s.mean for s in distance], [s.sd for s in distance]),
            },
            path,
            f"Ablation: {factor.key}",
        )
        names.append(path.name)
    overlay = {
        f"{label} (n={g.n})": (c.steps, c.mae_mean, c.mae_sd)
        for label, g in zip(labels, rows)
        if (c := curves.get(g.gid)) is not None
    }
    # replays of the same runs share one eye: curves that could only coincide are not overlaid
    one_eye = len({group_eyes(g) for g in rows}) == 1
    if overlay and not one_eye:
        path = figures.path(f"ablation_{_slug(factor.key)}_mae")
        if path is not None:
            plots.mean_sd_curves(overlay, path, f"Eye-movement MAE by {factor.key}")
            names.append(path.name)
    return names
