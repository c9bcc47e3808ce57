"""Pictures of learned dictionaries (paper §3.3; the binocular basis functions behind Fig. 5).

Every atom (a row of K = 2·p² elements) is drawn as its I0 half beside its I(t) half, two p×p
squares separated by a one-pixel gap, on mid-grey where 0 is grey and each atom pair is scaled
by its own largest |value|. Shifted-pair atoms show the same stripes displaced between halves.
The grid is a uint8 (H, W) array: ``SummaryWriter.add_image(tag, grid, dataformats="HW")`` or
:func:`save_png`.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import torch

_GREY = 128
_BACKGROUND = 0


def atom_grid(
    dictionary: torch.Tensor | np.ndarray,
    patch: int = 10,
    columns: int | None = None,
    zoom: int = 3,
    gap: int = 2,
) -> np.ndarray:
    """uint8 (H, W) grid of (I0-half | I(t)-half) atom pairs of an (N, 2·patch²) dictionary.

    ``columns`` pairs per row (default ≈ √N), each pixel drawn ``zoom``×``zoom``, ``gap`` black
    pixels between pairs.
    """
    atoms = (
        dictionary.detach().cpu().double().numpy()
        if isinstance(dictionary, torch.Tensor)
        else np.asarray(dictionary, dtype=np.float64)
    )
    if atoms.ndim != 2 or atoms.shape[1] != 2 * patch * patch:
        raise ValueError(
            f"dictionary must be (N, {2 * patch * patch}) for patch {patch}, "
            f"got shape {atoms.shape}"
        )
    if zoom < 1 or gap < 0:
        raise ValueError(f"zoom must be ≥ 1 and gap ≥ 0, got zoom={zoom}, gap={gap}")
    count = atoms.shape[0]
    columns = columns or max(1, math.ceil(math.sqrt(count)))
    rows = math.ceil(count / columns)

    peak = np.abs(atoms).max(axis=1, keepdims=True)
    scaled = np.divide(atoms, peak, out=np.zeros_like(atoms), where=peak > 0)
    pixels = np.clip(np.rint(_GREY + 127 * scaled), 0, 255).astype(np.uint8)
    halves = pixels.reshape(count, 2, patch, patch)

    pair_width = 2 * patch + 1
    cell_h, cell_w = patch + gap, pair_width + gap
    grid = np.full((rows * cell_h + gap, columns * cell_w + gap), _BACKGROUND, dtype=np.uint8)
    for index in range(count):
        top = gap + (index // columns) * cell_h
        left = gap + (index % columns) * cell_w
        grid[top : top + patch, left : left + patch] = halves[index, 0]
        grid[top : top + patch, left + patch : left + patch + 1] = _GREY
        grid[top : top + patch, left + patch + 1 : left + pair_width] = halves[index, 1]
    return np.kron(grid, np.ones((zoom, zoom), dtype=np.uint8)) if zoom > 1 else grid


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Write a uint8 (H, W) or (H, W, 3) RGB image as PNG; raises if OpenCV cannot write it."""
    path = Path(path)
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise ValueError(f"image must be uint8 (H,W) or (H,W,3), got {image.dtype} {image.shape}")
    path.parent.mkdir(parents=True, exist_ok=True)
    pixels = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    if not cv2.imwrite(str(path), pixels):
        raise OSError(f"could not write PNG to {path}")
    return path
