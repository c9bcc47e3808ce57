"""Figures in the manner of the paper's Fig. 7–11: MAE curves over training (with the moment the
perturbation starts), MAE per lateral position, and distance error against distance."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")  # headless: figures go to files
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def mae_curves(records: Sequence[dict], path: str | Path, title: str = "Eye-movement MAE",
               perturbation_at: int | None = None) -> Path:
    """Fig. 7–9: the sliding-window MAE (eq. 16) per lateral position against trials."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.array([r["steps"] for r in records])
    labels = list(records[-1]["mae_per_position"]) if records else []
    cmap = plt.get_cmap("viridis", max(len(labels), 2))
    for i, label in enumerate(labels):
        ax.plot(x, [r["mae_per_position"].get(label, np.nan) for r in records], color=cmap(i),
                lw=1, label=f"{label} cm")
    ax.plot(x, [r["mae"] for r in records], color="k", lw=2, label="all")
    if perturbation_at is not None:
        ax.axvline(perturbation_at, color="gray", ls="--", label="perturbation")
    ax.set_xlabel("iterations per robot")
    ax.set_ylabel("MAE (deg)")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def mae_per_position(results: dict[str, dict[str, float]], path: str | Path) -> Path:
    """MAE at the last iteration per lateral position, one bar group per policy mode."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    modes = list(results)
    labels = list(results[modes[0]])
    width = 0.8 / len(modes)
    for i, mode in enumerate(modes):
        ax.bar(np.arange(len(labels)) + i * width, [results[mode][k] for k in labels], width, label=mode)
    ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels)
    ax.set_xlabel("lateral position (cm)")
    ax.set_ylabel("MAE (deg)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def error_vs_distance(curves: dict[str, tuple[Sequence[float], Sequence[float]]], path: str | Path,
                      title: str = "Distance estimation error") -> Path:
    """Fig. 10–11: mean relative error (%) at each distance, one line per model."""
    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for name, (d, err) in curves.items():
        ax.plot(d, err, marker=".", lw=1, label=name)
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("error (%)")
    ax.set_title(title)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
