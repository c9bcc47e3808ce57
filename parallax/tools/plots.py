"""Figures in the manner of the paper's Fig. 7–11: MAE curves over training (with the moment the
perturbation starts), MAE per lateral position, and distance error against distance."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: figures go to files
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _set_title(ax, title: str) -> None:
    """Long titles (a group's settings) wrap instead of running off the figure."""
    lines = textwrap.wrap(title, 70) or [""]
    ax.set_title("\n".join(lines), fontsize=10 if len(lines) > 1 else None)


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def mae_curves(
    records: Sequence[dict],
    path: str | Path,
    title: str = "Eye-movement MAE",
    perturbation_at: int | None = None,
) -> Path:
    """Fig. 7–9: the sliding-window MAE (eq. 16) per lateral position against trials."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.array([r["steps"] for r in records])
    labels = list(records[-1]["mae_per_position"]) if records else []
    cmap = plt.get_cmap("viridis", max(len(labels), 2))
    for i, label in enumerate(labels):
        ax.plot(
            x,
            [r["mae_per_position"].get(label, np.nan) for r in records],
            color=cmap(i),
            lw=1,
            label=f"{label} cm",
        )
    ax.plot(x, [r["mae"] for r in records], color="k", lw=2, label="all")
    if perturbation_at is not None:
        ax.axvline(perturbation_at, color="gray", ls="--", label="perturbation")
    ax.set_xlabel("iterations per robot")
    ax.set_ylabel("MAE (deg)")
    ax.set_yscale("log")
    _set_title(ax, title)
    ax.legend(fontsize=6, ncol=2)
    return _save(fig, path)


def mae_per_position(results: dict[str, dict[str, float]], path: str | Path) -> Path:
    """MAE at the last iteration per lateral position, one bar group per policy mode."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    modes = list(results)
    labels = list(results[modes[0]])
    width = 0.8 / len(modes)
    for i, mode in enumerate(modes):
        ax.bar(
            np.arange(len(labels)) + i * width,
            [results[mode][k] for k in labels],
            width,
            label=mode,
        )
    ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels)
    ax.set_xlabel("lateral position (cm)")
    ax.set_ylabel("MAE (deg)")
    ax.legend()
    return _save(fig, path)


def error_vs_distance(
    curves: dict[str, tuple[Sequence[float], Sequence[float]]],
    path: str | Path,
    title: str = "Distance estimation error",
) -> Path:
    """Fig. 10–11: mean relative error (%) at each distance, one line per model."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for name, (d, err) in curves.items():
        ax.plot(d, err, marker=".", lw=1, label=name)
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("error (%)")
    _set_title(ax, title)
    ax.legend(fontsize=7)
    return _save(fig, path)


# --- figures of `parallax-report` (several seeds per curve) ---------------------------------------


def mean_sd_curves(
    curves: dict[str, tuple[Sequence[float], Sequence[float], Sequence[float]]],
    path: str | Path,
    title: str,
    *,
    ylabel: str = "MAE (deg)",
    xlabel: str = "iterations per robot",
    perturbation_at: float | None = None,
    thin_curves: dict[str, tuple[Sequence[float], Sequence[float]]] | None = None,
    log_y: bool = True,
) -> Path:
    """Fig. 7–9 over seeds: each curve is a mean (solid) with ±1 sd shaded; `thin_curves` (e.g. one
    per lateral position) are drawn as thin lines; a gray dashed line marks the perturbation."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 4))
    thin_curves = thin_curves or {}
    thin_colours = plt.get_cmap("viridis", max(len(thin_curves), 2))
    for i, (name, (x, y)) in enumerate(thin_curves.items()):
        ax.plot(x, y, color=thin_colours(i), lw=0.8, alpha=0.8, label=name)
    bold_colours = plt.get_cmap("tab10")
    for i, (name, (x, mean, sd)) in enumerate(curves.items()):
        x, mean, sd = (np.asarray(v, dtype=float) for v in (x, mean, sd))
        colour = "k" if len(curves) == 1 else bold_colours(i % 10)
        ax.plot(x, mean, color=colour, lw=2, label=name)
        low = mean - sd
        if log_y:  # a band reaching zero would stretch a log axis to nothing
            low = np.where(low > 0, low, np.nan)
        ax.fill_between(x, low, mean + sd, color=colour, alpha=0.2, lw=0)
    if perturbation_at is not None:
        ax.axvline(perturbation_at, color="gray", ls="--", label="perturbation")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if log_y:
        ax.set_yscale("log")
    _set_title(ax, title)
    ax.legend(fontsize=6, ncol=2)
    return _save(fig, path)


def error_vs_distance_with_band(
    lines: dict[str, tuple[Sequence[float], Sequence[float]]],
    path: str | Path,
    title: str = "Distance estimation error",
    *,
    band: tuple[str, Sequence[float], Sequence[float], Sequence[float], Sequence[float]]
    | None = None,
    markers: dict[str, tuple[Sequence[float], Sequence[float]]] | None = None,
) -> Path:
    """Fig. 10–11: error (%) against distance, one line per model; `band` = (name, d, mean, min,
    max) draws a group of models (the single-position runs) as its mean with dashed min and max,
    as the paper does; `markers` adds points (distances between the grid points)."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 3.8))
    if band is not None:
        name, d, mean, low, high = band
        ax.plot(d, mean, color="tab:blue", lw=1.5, label=f"{name}: mean")
        ax.plot(d, low, color="tab:blue", lw=0.8, ls="--", label=f"{name}: min / max")
        ax.plot(d, high, color="tab:blue", lw=0.8, ls="--")
    colours = plt.get_cmap("tab10")
    for i, (name, (d, err)) in enumerate(lines.items()):
        ax.plot(d, err, color=colours((i + 1) % 10), lw=1.2, label=name)
    for i, (name, (d, err)) in enumerate((markers or {}).items()):
        ax.plot(d, err, ls="none", marker="o", ms=4, color=colours((i + 1) % 10), label=name)
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("error (%)")
    _set_title(ax, title)
    ax.legend(fontsize=6)
    return _save(fig, path)


def ablation_bars(
    labels: Sequence[str],
    panels: dict[str, tuple[Sequence[float], Sequence[float]]],
    path: str | Path,
    title: str,
) -> Path:
    """One panel per quantity (e.g. final MAE, distance error): a bar per setting, mean with an
    sd error bar over seeds; a missing value (NaN) leaves its bar out and says so."""
    path = Path(path)
    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels) + 1, 3.6), squeeze=False)
    x = np.arange(len(labels))
    for ax, (name, (means, sds)) in zip(axes[0], panels.items()):
        means = np.asarray(means, dtype=float)
        sds = np.nan_to_num(np.asarray(sds, dtype=float))
        ax.bar(x, np.nan_to_num(means), yerr=sds, capsize=3, color="tab:blue", alpha=0.8)
        for i in np.flatnonzero(~np.isfinite(means)):
            ax.text(i, 0, "n/a", ha="center", va="bottom", fontsize=7)
        ax.set_xticks(x, labels, rotation=30, ha="right", fontsize=7)
        ax.set_title(name, fontsize=9)
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def learning_curves_by_robots(curves: dict[str, dict], path: str | Path, trials: int) -> Path:
    """Worst-position recent MAE against robot-iterations and against wall time (e.g. B = 1
    against B = 16): one line per run, from parallax.tools.analysis.time_to_learn.learning_curve."""
    fig, (by_steps, by_time) = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for label, curve in curves.items():
        by_steps.plot(curve["robot_iterations"], curve["worst_mae_deg"], label=label)
        by_time.plot(np.asarray(curve["wall_time_s"]) / 60.0, curve["worst_mae_deg"], label=label)
    by_steps.set_xlabel("robot-iterations (iterations × B)")
    by_time.set_xlabel("wall time (min)")
    by_steps.set_ylabel(f"worst position's MAE of the last {trials} trials (deg)")
    for ax in (by_steps, by_time):
        ax.grid(alpha=0.3)
    by_time.legend(fontsize=8)
    return _save(fig, Path(path))


def pursuit_landscape(results: dict[str, dict], path: str | Path) -> Path:
    """The policy's mean pan step E_π[a] and the reward against the pan's offset from α*, one line
    per run (``python -m parallax.tools.analysis.landscape RUN... --plot``): where E_π[a] has the
    sign of the offset, the eye is pushed further away from the target."""
    fig, (steps, rewards) = plt.subplots(1, 2, figsize=(11, 4), sharex=True)
    for label, result in results.items():
        steps.plot(result["offsets_deg"], result["mean_step_deg"], label=label)
        rewards.plot(result["offsets_deg"], result["reward"], label=label)
    steps.axhline(0.0, color="k", lw=0.6)
    steps.set_ylabel("policy's mean pan step E_π[a] (deg)")
    rewards.set_ylabel("reward −(e_C + e_F)")
    for ax in (steps, rewards):
        ax.axvline(0.0, color="k", lw=0.6, ls=":")
        ax.set_xlabel("pan − α* (deg)")
        ax.grid(alpha=0.3)
    steps.legend(fontsize=7)
    return _save(fig, Path(path))
