"""Dictionary learning on real photographs (paper §3.3): error falls, atoms become binocular,
and the trained coder is shift-sensitive — the property the pursuit reward rests on (eq. 6).

I(t) is I0 with its content moved right by ``shift`` pixels, so a patch of I(t) at column x is
the patch of I0 at column x − shift. The fast tests train one small dictionary directly on patch
pairs; the slow ones run the full two-scale coder on whole 256×256 frames.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from parallax.coding import MultiScaleCoder
from parallax.coding.dictionary import gradient_step_, random_dictionary, reconstruction_error
from parallax.coding.pursuit import matching_pursuit
from parallax.coding.retina import zero_mean_unit_norm

TRAIN_PHOTOS = ("camera", "astronaut", "coffee", "chelsea", "brick", "grass", "gravel")
HELD_OUT_PHOTOS = ("rocket", "immunohistochemistry")
PATCH, MARGIN = 10, 12


def _gray(name: str, halvings: int) -> np.ndarray:
    import skimage.data

    image = getattr(skimage.data, name)().astype(np.float32) / 255
    if image.ndim == 3:
        image = image @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    for _ in range(halvings):
        image = cv2.pyrDown(image)
    return image


@pytest.fixture(scope="module")
def photos() -> dict[str, list[np.ndarray]]:
    return {
        "train": [_gray(name, 1) for name in TRAIN_PHOTOS],
        "held_out": [_gray(name, 1) for name in HELD_OUT_PHOTOS],
    }


def _shifted_pairs(
    images: list[np.ndarray], shifts: np.ndarray, rng: np.random.Generator
) -> torch.Tensor:
    """(len(shifts), 200) normalised [I0 patch ; I(t) patch] pairs from random places."""
    count = len(shifts)
    which = rng.integers(len(images), size=count)
    offsets = np.arange(PATCH)
    pairs = np.empty((count, 2, PATCH, PATCH), dtype=np.float32)
    for index, image in enumerate(images):
        chosen = np.flatnonzero(which == index)
        height, width = image.shape
        ys = (
            rng.integers(0, height - PATCH, size=chosen.size)[:, None, None]
            + offsets[None, :, None]
        )
        xs = (
            rng.integers(MARGIN, width - PATCH - MARGIN, size=chosen.size)[:, None, None]
            + offsets[None, None, :]
        )
        pairs[chosen, 0] = image[ys, xs]
        pairs[chosen, 1] = image[ys, xs - shifts[chosen, None, None]]
    halves = zero_mean_unit_norm(torch.from_numpy(pairs.reshape(count, 2, PATCH * PATCH)))
    return halves.reshape(count, 2 * PATCH * PATCH)


def _train(
    images: list[np.ndarray],
    draw_shifts,
    updates: int,
    atoms: int = 64,
    batch: int = 100,
    seed: int = 0,
) -> tuple[torch.Tensor, list[float]]:
    rng = np.random.default_rng(seed)
    dictionary = random_dictionary(atoms, 2 * PATCH * PATCH, torch.Generator().manual_seed(seed))
    errors = []
    for _ in range(updates):
        pairs = _shifted_pairs(images, draw_shifts(rng, batch), rng)
        code = matching_pursuit(pairs, dictionary, sparsity=10)
        errors.append(reconstruction_error(pairs[None], code.residuals[None]).item())
        gradient_step_(dictionary, code, learning_rate=0.2)
    return dictionary, errors


def _half_correlation(atoms: np.ndarray, shift: int) -> np.ndarray:
    """Per atom: correlation of the I(t) half with the I0 half moved right by ``shift`` px,
    over the columns they share."""
    first, second = atoms[:, 0], atoms[:, 1]
    if shift > 0:
        first, second = first[:, :, :-shift], second[:, :, shift:]
    elif shift < 0:
        first, second = first[:, :, -shift:], second[:, :, :shift]
    first = first.reshape(len(atoms), -1) - first.reshape(len(atoms), -1).mean(1, keepdims=True)
    second = second.reshape(len(atoms), -1) - second.reshape(len(atoms), -1).mean(1, keepdims=True)
    return (first * second).sum(1) / np.sqrt((first**2).sum(1) * (second**2).sum(1) + 1e-12)


def _mean_error(dictionary: torch.Tensor, images: list[np.ndarray], shift: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    pairs = _shifted_pairs(images, np.full(3000, shift), rng)
    code = matching_pursuit(pairs, dictionary, sparsity=10)
    return reconstruction_error(pairs[None], code.residuals[None]).item()


def test_error_falls_and_atoms_learn_the_trained_shift(photos) -> None:
    trained_shift = 2
    dictionary, errors = _train(
        photos["train"], lambda rng, n: np.full(n, trained_shift), updates=1200
    )
    assert np.mean(errors[-50:]) < 0.5 * np.mean(errors[:50])

    atoms = dictionary.numpy().reshape(-1, 2, PATCH, PATCH)
    at_trained = np.median(_half_correlation(atoms, trained_shift))
    elsewhere = [np.median(_half_correlation(atoms, shift)) for shift in (-2, -1, 0, 4)]
    assert at_trained > 0.7, "the I(t) half of an atom should be its I0 half moved by the shift"
    assert at_trained > max(elsewhere) + 0.3
    initial = (
        random_dictionary(64, 200, torch.Generator().manual_seed(0))
        .numpy()
        .reshape(-1, 2, PATCH, PATCH)
    )
    assert abs(np.median(_half_correlation(initial, trained_shift))) < 0.1


def test_trained_dictionary_codes_aligned_pairs_best(photos) -> None:
    def mostly_small(rng: np.random.Generator, count: int) -> np.ndarray:
        return np.clip(np.rint(rng.laplace(0.0, 1.0, count)), -4, 4).astype(int)

    dictionary, _ = _train(photos["train"], mostly_small, updates=1200, seed=1)
    errors = {
        shift: _mean_error(dictionary, photos["held_out"], shift, seed=2) for shift in range(-5, 6)
    }
    assert min(errors, key=errors.get) == 0
    for magnitude in range(1, 5):
        for sign in (-1, 1):
            assert errors[sign * magnitude] > errors[sign * (magnitude - 1)], errors
    assert errors[5] > 1.4 * errors[0] and errors[-5] > 1.4 * errors[0]


# --- the full two-scale coder on whole frames (slow) ---------------------------------------

SPECS = {
    "coarse": {"window": 250, "subsample": 8, "patch": 10, "stride": 1},
    "fine": {"window": 150, "subsample": 2, "patch": 10, "stride": 4},
}


def _frame_pair(image: np.ndarray, shift: int, rng: np.random.Generator, size: int = 256):
    height, width = image.shape[:2]
    top = int(rng.integers(0, height - size + 1))
    left = int(rng.integers(40, width - size - 40 + 1))
    return image[None, top : top + size, left : left + size], image[
        None, top : top + size, left - shift : left - shift + size
    ]


@pytest.mark.slow
def test_full_coder_learns_and_becomes_shift_sensitive() -> None:
    import skimage.data

    train = [
        getattr(skimage.data, name)()
        for name in ("astronaut", "coffee", "chelsea", "brick", "gravel", "camera")
    ]
    held_out = [skimage.data.rocket(), skimage.data.immunohistochemistry()]
    coder = MultiScaleCoder(["coarse", "fine"], SPECS, seed=0, image_size=256, learning_rate=0.2)
    rng = np.random.default_rng(0)
    rewards = []
    for _ in range(3000):
        shift = int(np.clip(np.rint(rng.laplace(0.0, 6.0)), -32, 32))
        reference, current = _frame_pair(train[rng.integers(len(train))], shift, rng)
        coder.set_reference(reference)
        rewards.append(coder(current).reward.item())
    assert np.mean(rewards[-200:]) > 0.6 * np.mean(rewards[:200])  # rewards are negative

    coder.learn = False
    evaluation = np.random.default_rng(1)
    frames = [_frame_pair(held_out[index % 2], 0, evaluation) for index in range(8)]
    errors, aligned_activity = {}, torch.zeros(coder.state_dim)
    for shift in (0, 2, 4, 8, 16, 32):
        total = 0.0
        for reference, _ in frames:
            coder.set_reference(reference)
            output = coder(np.roll(reference, shift, axis=2))
            total -= output.reward.item()
            if shift == 0:
                aligned_activity += output.state[0]
        errors[shift] = total / len(frames)
    shifts = sorted(errors)
    assert all(errors[a] < errors[b] for a, b in zip(shifts, shifts[1:])), errors

    # The atoms that code aligned views are binocular: their two halves are nearly the same.
    coarse_activity = aligned_activity[: coder.atoms].numpy()
    most_used = np.argsort(-coarse_activity)[:50]
    atoms = coder.dictionaries["coarse"].numpy().reshape(-1, 2, PATCH, PATCH)
    assert np.median(_half_correlation(atoms[most_used], 0)) > 0.6
