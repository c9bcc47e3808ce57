"""Retina of the sensory coder (paper §3.3): windows, pyramid, patches, normalisation."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from parallax.coding.retina import (
    ScaleSpec,
    as_gray_batch,
    centre_window,
    extract_patches,
    prepare_reference,
    pyramid_down,
    pyramid_down_torch,
    rgb_to_gray_torch,
    scale_patches,
    stack_pair,
    zero_mean_unit_norm,
)

COARSE = ScaleSpec(window=250, subsample=8, patch=10, stride=1)
FINE = ScaleSpec(window=150, subsample=2, patch=10, stride=4)


def _random_images(batch: int, size: int = 256, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (batch, size, size, 3), dtype=np.uint8)


@pytest.mark.parametrize(("spec", "side", "count"), [(COARSE, 32, 529), (FINE, 75, 289)])
def test_patch_counts_and_shapes(spec: ScaleSpec, side: int, count: int) -> None:
    assert spec.subsampled_size == side
    assert spec.patch_count == count and spec.dim == 200
    gray = as_gray_batch(_random_images(3))
    patches = scale_patches(gray, spec)
    assert patches.shape == (3, count, 100)
    assert patches.dtype == torch.float32


@pytest.mark.parametrize("shape", [(250, 250), (150, 150), (125, 125), (63, 63), (63, 64), (7, 9)])
def test_pyramid_matches_opencv(shape: tuple[int, int]) -> None:
    image = np.random.default_rng(1).random(shape).astype(np.float32)
    theirs = cv2.pyrDown(image)
    for pyramid in (pyramid_down_torch, pyramid_down):
        ours = pyramid(torch.from_numpy(image)[None], 1)[0].numpy()
        assert ours.shape == theirs.shape
        np.testing.assert_allclose(ours, theirs, atol=1e-4)


def test_three_levels_match_repeated_opencv_on_a_photograph() -> None:
    import skimage.data

    image = skimage.data.camera()[100:350, 120:370].astype(np.float32) / 255
    expected = image
    for _ in range(3):
        expected = cv2.pyrDown(expected)
    batch = torch.from_numpy(np.stack([image, image[::-1].copy()]))
    for pyramid in (pyramid_down_torch, pyramid_down):
        ours = pyramid(batch, 3).numpy()
        np.testing.assert_allclose(ours[0], expected, atol=1e-4)
        np.testing.assert_allclose(ours[1], pyramid_down_torch(batch[1:], 3)[0].numpy(), atol=1e-4)


def test_opencv_without_worker_threads_gives_the_same_patches() -> None:
    # parallax.experiment.Experiment turns OpenCV's worker threads off; the retina must not change
    rgb = _random_images(2)
    previous = cv2.getNumThreads()
    try:
        cv2.setNumThreads(max(2, previous))
        threaded = [scale_patches(as_gray_batch(rgb), spec) for spec in (COARSE, FINE)]
        blurred_threaded = cv2.GaussianBlur(
            rgb[0], (0, 0), sigmaX=2.0, borderType=cv2.BORDER_REFLECT_101
        )
        cv2.setNumThreads(0)
        alone = [scale_patches(as_gray_batch(rgb), spec) for spec in (COARSE, FINE)]
        blurred_alone = cv2.GaussianBlur(
            rgb[0], (0, 0), sigmaX=2.0, borderType=cv2.BORDER_REFLECT_101
        )
    finally:
        cv2.setNumThreads(previous)
    for a, b in zip(threaded, alone):
        assert torch.equal(a, b)
    assert np.array_equal(blurred_threaded, blurred_alone)


def test_grayscale_matches_opencv_and_accepts_every_input_form() -> None:
    rgb = _random_images(2, size=40)
    expected = np.stack(
        [cv2.cvtColor(image.astype(np.float32), cv2.COLOR_RGB2GRAY) for image in rgb]
    )
    np.testing.assert_allclose(as_gray_batch(rgb).numpy() * 255, expected, atol=1e-3)
    np.testing.assert_allclose(
        as_gray_batch(torch.from_numpy(rgb)).numpy() * 255, expected, atol=1e-3
    )
    np.testing.assert_allclose(
        rgb_to_gray_torch(torch.from_numpy(rgb)).numpy(), expected, atol=1e-3
    )
    gray_float = expected / 255
    np.testing.assert_allclose(as_gray_batch(gray_float).numpy(), gray_float, atol=1e-6)
    flipped = rgb[:, ::-1]  # a non-contiguous numpy view
    np.testing.assert_allclose(as_gray_batch(flipped).numpy() * 255, expected[:, ::-1], atol=1e-3)


@pytest.mark.parametrize(
    "bad", [np.zeros((2, 8, 8, 4)), np.zeros((8, 8)), np.zeros((1, 2, 8, 8, 3))]
)
def test_bad_image_shapes_are_refused(bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="shape"):
        as_gray_batch(bad)


def test_centre_window_is_central_and_checks_size() -> None:
    gray = torch.arange(10 * 12, dtype=torch.float32).reshape(1, 10, 12)
    window = centre_window(gray, 4)
    assert torch.equal(window, gray[:, 3:7, 4:8])
    with pytest.raises(ValueError, match="window 11"):
        centre_window(gray, 11)


def test_patches_are_row_major_windows_at_the_stride() -> None:
    image = torch.arange(20 * 20, dtype=torch.float32).reshape(1, 20, 20)
    patches = extract_patches(image, patch=10, stride=4)
    per_side = (20 - 10) // 4 + 1
    assert patches.shape == (1, per_side**2, 100)
    second_row_first_column = patches[0, per_side]
    assert torch.equal(second_row_first_column, image[0, 4:14, 0:10].reshape(-1))


def test_per_half_normalisation_gives_zero_mean_unit_norm_halves() -> None:
    gray = as_gray_batch(_random_images(2, seed=3))
    gray_later = as_gray_batch(_random_images(2, seed=4))
    reference = prepare_reference(scale_patches(gray, FINE), "per_half")
    pairs = stack_pair(reference, scale_patches(gray_later, FINE), "per_half")
    assert pairs.shape == (2, 289, 200)
    for half in (pairs[..., :100], pairs[..., 100:]):
        torch.testing.assert_close(half.mean(-1), torch.zeros(2, 289), atol=1e-6, rtol=0)
        torch.testing.assert_close(half.norm(dim=-1), torch.ones(2, 289), atol=1e-5, rtol=0)
    # The I0 half is exactly the cached reference: computed once per stimulus.
    assert torch.equal(pairs[..., :100], reference)


def test_joint_normalisation_normalises_the_whole_pair_and_keeps_contrast_ratio() -> None:
    rng = np.random.default_rng(5)
    reference_raw = torch.from_numpy(rng.random((1, 4, 100)).astype(np.float32))
    patch_mean = reference_raw.mean(-1, keepdim=True)
    current_raw = patch_mean + 0.25 * (reference_raw - patch_mean)  # a quarter of the contrast
    pairs = stack_pair(prepare_reference(reference_raw, "joint"), current_raw, "joint")
    torch.testing.assert_close(pairs.mean(-1), torch.zeros(1, 4), atol=1e-6, rtol=0)
    torch.testing.assert_close(pairs.norm(dim=-1), torch.ones(1, 4), atol=1e-5, rtol=0)
    ratio = pairs[..., 100:].norm(dim=-1) / pairs[..., :100].norm(dim=-1)
    torch.testing.assert_close(ratio, torch.full((1, 4), 0.25), atol=1e-4, rtol=0)


def test_constant_patches_become_zero_not_nan() -> None:
    flat = torch.full((1, 3, 100), 0.7)
    tiny_noise = flat + 1e-9 * torch.randn(1, 3, 100, generator=torch.Generator().manual_seed(0))
    for vectors in (flat, tiny_noise, torch.zeros(1, 3, 100)):
        normalised = zero_mean_unit_norm(vectors)
        assert torch.equal(normalised, torch.zeros_like(vectors))
    one_grey_level = flat.clone()
    one_grey_level[..., 0] += 1 / 255
    assert torch.isclose(zero_mean_unit_norm(one_grey_level).norm(dim=-1), torch.ones(1, 3)).all()


def test_a_scale_spec_comes_from_its_config_mapping() -> None:
    # its ranges are parallax.config's (tests/config/test_bad_input.py: coder.scale_specs.*)
    assert ScaleSpec.from_mapping({"window": 250, "subsample": 8, "patch": 10, "stride": 1}) == (
        COARSE
    )
