"""Stimulus textures for the panel, "an object with an interchangeable texture" (paper §4.1).

The paper used "a set of 100 different images". Without network access we cut them from the
real photographs scikit-image ships inside its package: square crops at varied positions and
scales, rejecting flat or mostly black crops and crops that overlap an earlier one too much. The
held-out split comes from photographs never used for training. Alternatives: a folder of the
user's own images (``source="dir"``), or procedural textures — dead leaves or 1/f noise — as an
ablation (``source="procedural"``).

A set is decoded once per process and shared by every environment (``load_stimuli`` caches it);
arrays are read-only.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from parallax.checks import Checks
from parallax.envs.settings import SPLITS, StimuliConfig

#: Photographs for training textures (names of ``skimage.data`` loaders; motorcycle = its left
#: view).
TRAIN_PHOTOS = (
    "astronaut",
    "brick",
    "camera",
    "chelsea",
    "coffee",
    "coins",
    "grass",
    "immunohistochemistry",
    "motorcycle",
    "rocket",
)
#: Photographs for held-out textures, disjoint from ``TRAIN_PHOTOS``.
HELDOUT_PHOTOS = ("gravel", "moon", "page", "text", "retina")
#: The still background behind the panel; in neither split.
BACKGROUND_PHOTO = "cell"

DEFAULT_COUNT = {"train": 120, "heldout": 40}
SETTING_KEYS = tuple(spec.name for spec in dataclasses.fields(StimuliConfig))

# Crop acceptance: side as a fraction of the photo's shorter side, least contrast, most
# near-black pixels, most overlap (intersection over union) with an accepted crop.
_CROP_SCALE = (0.35, 0.7)
_MIN_GRAY_STD = 12.0
_MAX_DARK_FRACTION = 0.25
_MAX_IOU = 0.5
_CROP_ATTEMPTS = 4000


@dataclass(frozen=True, eq=False)  # identity: sets are cached and shared, never compared by value
class StimulusSet:
    """Square RGB textures (N, R, R, 3) uint8 and where each one came from."""

    textures: np.ndarray
    names: tuple[str, ...]
    source: str
    split: str

    @property
    def count(self) -> int:
        return int(self.textures.shape[0])

    @property
    def resolution(self) -> int:
        return int(self.textures.shape[1])


class StimulusError(ValueError):
    """A stimulus setting that cannot work: ``stimuli.<key>=<value>: <reason>``."""

    def __init__(self, key: str, value: Any, reason: str):
        super().__init__(f"stimuli.{key}={value!r}: {reason}")
        self.key, self.value, self.reason = key, value, reason

    def __reduce__(self):
        return (type(self), (self.key, self.value, self.reason))


_CACHE: dict[tuple, StimulusSet] = {}
_PHOTO_CACHE: dict[str, np.ndarray] = {}


def load_stimuli(settings: Mapping[str, Any] | None = None) -> StimulusSet:
    """The texture set described by ``settings`` (keys: ``SETTING_KEYS``), built once per
    process."""
    options = normalise_settings(settings)
    key = _cache_key(options)
    if key not in _CACHE:
        _CACHE[key] = _build(options)
    return _CACHE[key]


def normalise_settings(settings: Mapping[str, Any] | None) -> dict[str, Any]:
    """The settings with the schema's defaults filled in (env.stimuli, whose values
    parallax.config checks); raises StimulusError for a key it does not know or a folder that
    is not there."""
    given = dict(settings or {})
    unknown = sorted(set(given) - set(SETTING_KEYS))
    if unknown:
        raise StimulusError(
            unknown[0], given[unknown[0]], f"no such setting; known: {', '.join(SETTING_KEYS)}"
        )
    options = {**dataclasses.asdict(StimuliConfig()), **given}
    if options["dir"] is not None and options["source"] == "skimage":
        # `stimuli.dir=<folder>` on top of the shipped source means the user's images
        options["source"] = "dir"
    folder = options["dir"]
    if options["source"] == "dir" and not (folder and Path(folder).expanduser().is_dir()):
        raise StimulusError("dir", folder, "is not a folder")
    options["resolution"] = int(options["resolution"])
    options["seed"] = int(options["seed"])
    options["count"] = None if options["count"] is None else int(options["count"])
    return options


def _cache_key(options: dict[str, Any]) -> tuple:
    key = tuple(sorted(options.items()))
    if options["source"] == "dir":
        # A folder's contents may change between calls: the listing is part of the key.
        folder = Path(options["dir"]).expanduser().resolve()
        listing = tuple(
            (p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in _image_candidates(folder)
        )
        key += (("listing", listing),)
    return key


def _build(options: dict[str, Any]) -> StimulusSet:
    source, split, resolution = options["source"], options["split"], options["resolution"]
    if source == "skimage":
        count = options["count"] or DEFAULT_COUNT[split]
        photos = TRAIN_PHOTOS if split == "train" else HELDOUT_PHOTOS
        textures, names = _photo_crops(photos, count, resolution, options["seed"])
    elif source == "procedural":
        count = options["count"] or DEFAULT_COUNT[split]
        textures, names = _procedural(options["kind"], split, count, resolution, options["seed"])
    else:
        textures, names = _folder_images(options["dir"], options["count"], resolution)
    stack = np.ascontiguousarray(np.stack(textures))
    stack.setflags(write=False)
    return StimulusSet(textures=stack, names=tuple(names), source=source, split=split)


# --- photographs shipped with scikit-image ---------------------------------------------------
def photo(name: str) -> np.ndarray:
    """An RGB uint8 photograph from scikit-image's package data (decoded once per process)."""
    if name not in _PHOTO_CACHE:
        import skimage.data

        image = (
            skimage.data.stereo_motorcycle()[0]
            if name == "motorcycle"
            else getattr(skimage.data, name)()
        )
        image = np.asarray(image)
        if image.ndim == 2:
            image = np.repeat(image[:, :, None], 3, axis=2)
        image = np.ascontiguousarray(image[:, :, :3].astype(np.uint8))
        image.setflags(write=False)
        _PHOTO_CACHE[name] = image
    return _PHOTO_CACHE[name]


def _photo_crops(
    photos: tuple[str, ...], count: int, resolution: int, seed: int
) -> tuple[list[np.ndarray], list[str]]:
    per_photo = math.ceil(count / len(photos))
    try:
        crops = [
            _distinct_crops(name, index, per_photo, resolution, seed)
            for index, name in enumerate(photos)
        ]
    except ValueError as error:
        raise StimulusError("count", count, str(error)) from None
    # Interleave photographs, so that a small set still spans all of them.
    ordered = [crops[p][k] for k in range(per_photo) for p in range(len(photos))]
    return [t for t, _ in ordered[:count]], [n for _, n in ordered[:count]]


def _distinct_crops(
    name: str, photo_index: int, wanted: int, resolution: int, seed: int
) -> list[tuple[np.ndarray, str]]:
    image = photo(name)
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    height, width = gray.shape
    shorter = min(height, width)
    rng = np.random.default_rng([seed, photo_index, 7919])
    accepted: list[tuple[int, int, int]] = []
    for _ in range(_CROP_ATTEMPTS):
        if len(accepted) == wanted:
            break
        side = int(round(rng.uniform(*_CROP_SCALE) * shorter))
        top = int(rng.integers(0, height - side + 1))
        left = int(rng.integers(0, width - side + 1))
        patch = gray[top : top + side, left : left + side]
        if patch.std() < _MIN_GRAY_STD or np.mean(patch < 16) > _MAX_DARK_FRACTION:
            continue
        if any(_iou((top, left, side), other) > _MAX_IOU for other in accepted):
            continue
        accepted.append((top, left, side))
    if len(accepted) < wanted:
        raise ValueError(
            f"{wanted} crops per photograph are needed but {name!r} gives only "
            f"{len(accepted)} distinct ones; ask for fewer or use stimuli.source=procedural"
        )
    out = []
    for top, left, side in accepted:
        crop = image[top : top + side, left : left + side]
        out.append((_resize_square(crop, resolution), f"{name}[y={top},x={left},side={side}]"))
    return out


def _iou(a: tuple[int, int, int], b: tuple[int, int, int]) -> float:
    (ta, la, sa), (tb, lb, sb) = a, b
    dy = max(0, min(ta + sa, tb + sb) - max(ta, tb))
    dx = max(0, min(la + sa, lb + sb) - max(la, lb))
    inter = dx * dy
    return inter / (sa * sa + sb * sb - inter)


def _resize_square(image: np.ndarray, resolution: int) -> np.ndarray:
    height, width = image.shape[:2]
    side = min(height, width)
    top, left = (height - side) // 2, (width - side) // 2
    square = image[top : top + side, left : left + side]
    shrinking = side >= resolution
    return cv2.resize(
        square,
        (resolution, resolution),
        interpolation=cv2.INTER_AREA if shrinking else cv2.INTER_CUBIC,
    )


# --- the user's own images -------------------------------------------------------------------
def _image_candidates(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))


def _folder_images(
    folder_name: str, count: int | None, resolution: int
) -> tuple[list[np.ndarray], list[str]]:
    folder = Path(folder_name).expanduser().resolve()
    textures, names, skipped = [], [], []
    for path in _image_candidates(folder):
        if count is not None and len(textures) == count:
            break
        image = cv2.imdecode(np.fromfile(str(path), dtype=np.uint8), cv2.IMREAD_COLOR)
        if image is None or min(image.shape[:2]) < 2:
            skipped.append(path.name)
            continue
        textures.append(_resize_square(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), resolution))
        names.append(path.name)
    if not textures:
        raise StimulusError(
            "dir",
            folder_name,
            f"holds no readable image ({len(skipped)} file(s) tried); put PNG, JPEG, BMP or "
            "TIFF images there",
        )
    if count is not None and len(textures) < count:
        raise StimulusError(
            "count", count, f"the folder {folder_name} has only {len(textures)} readable image(s)"
        )
    if skipped:
        warnings.warn(
            f"stimuli.dir={folder_name!r}: skipped {len(skipped)} unreadable file(s): "
            f"{', '.join(skipped)}",
            stacklevel=3,
        )
    return textures, names


# --- procedural textures (ablation) ----------------------------------------------------------
def _procedural(
    kind: str, split: str, count: int, resolution: int, seed: int
) -> tuple[list[np.ndarray], list[str]]:
    split_code = SPLITS.index(split)  # disjoint random streams for the two splits
    make = {"dead_leaves": _dead_leaves, "pink_noise": _pink_noise}[kind]
    textures = [
        make(np.random.default_rng([seed, split_code, i, 104729]), resolution) for i in range(count)
    ]
    return textures, [f"{kind}[{split} {i}]" for i in range(count)]


def _dead_leaves(rng: np.random.Generator, resolution: int) -> np.ndarray:
    """Occluding discs with radii drawn from p(r) ∝ r⁻³: scale-invariant like natural images."""
    image = np.full((resolution, resolution, 3), 128, dtype=np.uint8)
    r_min, r_max = max(1.0, resolution / 128), resolution / 5
    discs = 12 * resolution
    u = rng.random(discs)
    radii = (r_min**-2 - u * (r_min**-2 - r_max**-2)) ** -0.5
    centres = rng.integers(0, resolution, size=(discs, 2)).tolist()
    colours = rng.integers(0, 256, size=(discs, 3)).tolist()
    # Plain Python numbers: cv2 converts NumPy scalars slowly.
    for centre, radius, colour in zip(centres, np.rint(radii).astype(int).tolist(), colours):
        cv2.circle(image, tuple(centre), radius, tuple(colour), -1, cv2.LINE_AA)
    return image


def _pink_noise(rng: np.random.Generator, resolution: int) -> np.ndarray:
    """Noise with a 1/f amplitude spectrum, per colour channel, scaled to 0..255."""
    fy = np.fft.fftfreq(resolution)[:, None]
    fx = np.fft.rfftfreq(resolution)[None, :]
    frequency = np.hypot(fx, fy)
    frequency[0, 0] = np.inf  # no DC: zero mean
    white = rng.standard_normal((3, resolution, resolution))
    field = np.fft.irfft2(np.fft.rfft2(white) / frequency, s=(resolution, resolution))
    spread = field.std(axis=(1, 2), keepdims=True)
    scaled = np.clip(field / (2.5 * spread) * 127.5 + 127.5, 0, 255)
    return np.ascontiguousarray(scaled.transpose(1, 2, 0)).astype(np.uint8)


def background_image(width: int, height: int) -> np.ndarray:
    """The still background (RGB uint8, height×width), from a photograph in neither split."""
    image = photo(BACKGROUND_PHOTO)
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)


__all__ = [
    "StimulusError",
    "StimulusSet",
    "load_stimuli",
    "normalise_settings",
    "photo",
    "background_image",
    "TRAIN_PHOTOS",
    "HELDOUT_PHOTOS",
    "BACKGROUND_PHOTO",
    "SETTING_KEYS",
]


def check_loadable(check: Checks) -> None:
    """Raise ConfigError for env.stimuli settings that give no textures (a folder without
    readable images, …): the set is built here, once per process, as the run will build it."""
    try:
        load_stimuli(check.get("env.stimuli"))
    except StimulusError as error:
        check.fail(f"env.stimuli.{error.key}", error.value, error.reason)
