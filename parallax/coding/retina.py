"""Retina: the preprocessing of the sensory coding model (paper §3.3, Fig. 5).

An eye image becomes, per scale, a set of patch vectors γ_i^j:
grayscale → centre window (250 px coarse, 150 px fine) → Gaussian pyramid (×8 coarse, ×2 fine)
→ 10×10 patches at a stride of 1 px (coarse) or 4 px (fine) → zero mean and unit norm → the
reference patch of I0 stacked over the patch of I(t), K = 2·10·10 = 200 elements.

Tensors in, tensors out, on the dictionaries' device. On the CPU the grey conversion and the
pyramid call OpenCV (``cvtColor``, ``pyrDown``: on images this small a torch convolution costs
many times more); elsewhere a torch copy of ``pyrDown`` (5-tap binomial kernel,
BORDER_REFLECT_101, output size ⌈n/2⌉) runs; ``tests/coding/test_retina.py`` checks that both
agree with OpenCV.

Normalisation (``"per_half"`` or ``"joint"``):

* ``per_half`` — each image's patch (each 100-element half) is made zero mean and unit norm
  separately, as in the public active-efficient-coding implementations; ‖γ‖² is then 2.
* ``joint`` — the stacked 200-vector as a whole is made zero mean and unit norm, which keeps the
  contrast ratio between I0 and I(t); ‖γ‖² is then 1.

A (half-)patch whose centred norm is at most ``NEAR_CONSTANT_TOLERANCE``·√n·|mean| (a flat region:
sky, floor, an untextured wall) becomes exactly zero instead of amplified rounding noise or NaN.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F

#: Luma weights of OpenCV's RGB→GRAY conversion (ITU-R BT.601).
GRAY_WEIGHTS = (0.299, 0.587, 0.114)

#: A patch counts as constant when its centred norm is at most this · √n · |mean|: far above the
#: float32 rounding left by mean subtraction (~1e-7 relative), far below one grey level of an
#: 8-bit image (1/255 ≈ 4e-3 relative).
NEAR_CONSTANT_TOLERANCE = 1e-5


_BINOMIAL_5 = (1.0, 4.0, 6.0, 4.0, 1.0)


@dataclass(frozen=True)
class ScaleSpec:
    """Geometry of one scale: centre window, pyramid sub-sampling factor, patch side, stride."""

    window: int
    subsample: int
    patch: int
    stride: int

    @classmethod
    def from_mapping(cls, spec: Mapping[str, Any]) -> ScaleSpec:
        """From a config mapping (coder.scale_specs.<name>, checked by parallax.config)."""
        return cls(**{key: int(spec[key]) for key in ("window", "subsample", "patch", "stride")})

    @property
    def pyramid_levels(self) -> int:
        return int(round(math.log2(self.subsample)))

    @property
    def subsampled_size(self) -> int:
        """Side of the window after the pyramid (pyrDown maps n to ⌈n/2⌉): 250 → 32, 150 → 75."""
        size = self.window
        for _ in range(self.pyramid_levels):
            size = (size + 1) // 2
        return size

    @property
    def patches_per_side(self) -> int:
        return (self.subsampled_size - self.patch) // self.stride + 1

    @property
    def patch_count(self) -> int:
        """P_N, patches per image: 23² = 529 coarse, 17² = 289 fine."""
        return self.patches_per_side**2

    @property
    def half_dim(self) -> int:
        return self.patch * self.patch

    @property
    def dim(self) -> int:
        """K, the length of a stacked [I0 ; I(t)] patch vector: 200."""
        return 2 * self.half_dim


def as_gray_batch(images: Any, device: torch.device | None = None) -> torch.Tensor:
    """(B,H,W,3) RGB or (B,H,W) gray, uint8 or float, tensor or array → (B,H,W) float32 gray.

    uint8 is scaled to [0, 1]; float input keeps its scale (normalisation removes it anyway).
    """
    if isinstance(images, torch.Tensor):
        tensor = images.detach()
    elif isinstance(images, np.ndarray):
        tensor = torch.from_numpy(np.ascontiguousarray(images))
    else:
        raise ValueError(
            f"images must be a torch tensor or a numpy array, got {type(images).__name__}"
        )
    if tensor.dim() == 4 and tensor.shape[-1] != 3:
        raise ValueError(f"RGB images must be (B,H,W,3), got shape {tuple(tensor.shape)}")
    if tensor.dim() not in (3, 4):
        raise ValueError(
            f"images must be (B,H,W,3) RGB or (B,H,W) gray, got shape {tuple(tensor.shape)}"
        )
    if tensor.dtype == torch.bool or tensor.is_complex():
        raise ValueError(f"images must be uint8 or float, got dtype {tensor.dtype}")
    scale = 1.0 / 255.0 if tensor.dtype == torch.uint8 else 1.0
    if tensor.dim() == 4:
        tensor = (
            rgb_to_gray_opencv(tensor) if tensor.device.type == "cpu" else rgb_to_gray_torch(tensor)
        )
    else:
        tensor = tensor.to(dtype=torch.float32)
    if scale != 1.0:
        tensor.mul_(scale)  # a fresh float copy of uint8 input: scaling in place is safe
    return tensor.to(device=device) if device is not None else tensor


def rgb_to_gray_opencv(rgb: torch.Tensor) -> torch.Tensor:
    """(B,H,W,3) CPU tensor → (B,H,W) float32 by cv2.cvtColor, unrounded (quicker than torch)."""
    pixels = rgb.contiguous().numpy()
    gray = np.empty(pixels.shape[:3], dtype=np.float32)
    for image, out in zip(pixels, gray):  # straight into the batch: no np.stack copy
        cv2.cvtColor(image.astype(np.float32, copy=False), cv2.COLOR_RGB2GRAY, dst=out)
    return torch.from_numpy(gray)


def rgb_to_gray_torch(rgb: torch.Tensor) -> torch.Tensor:
    """(B,H,W,3) tensor on any device → (B,H,W) float32 with OpenCV's luma weights."""
    weights = torch.tensor(GRAY_WEIGHTS, dtype=torch.float32, device=rgb.device)
    return rgb.to(dtype=torch.float32) @ weights


def centre_window(gray: torch.Tensor, window: int) -> torch.Tensor:
    """The central window×window crop of (B,H,W) images (top-left rounding down when odd)."""
    height, width = gray.shape[-2:]
    if window > height or window > width:
        raise ValueError(f"window {window} px does not fit in images of {height}×{width} px")
    top, left = (height - window) // 2, (width - window) // 2
    return gray[..., top : top + window, left : left + window]


def pyramid_down(gray: torch.Tensor, levels: int) -> torch.Tensor:
    """``levels`` steps of cv2.pyrDown on (B,H,W) float32: OpenCV on the CPU, torch elsewhere."""
    if gray.device.type != "cpu" or levels == 0:
        return pyramid_down_torch(gray, levels)
    reduced = []
    for image in gray.numpy():
        for _ in range(levels):
            image = cv2.pyrDown(np.ascontiguousarray(image))
        reduced.append(image)
    return torch.from_numpy(np.stack(reduced))


def pyramid_down_torch(gray: torch.Tensor, levels: int) -> torch.Tensor:
    """cv2.pyrDown in torch: blur with the 5-tap binomial (reflect-101 borders), keep the even
    pixels."""
    taps = torch.tensor(_BINOMIAL_5, dtype=gray.dtype, device=gray.device) / 16.0
    kernel = (taps[:, None] * taps[None, :])[None, None]
    image = gray[:, None]
    for _ in range(levels):
        if min(image.shape[-2:]) < 3:
            raise ValueError(
                f"image of {tuple(image.shape[-2:])} px is too small for another pyramid level"
            )
        # mode="reflect" is OpenCV's BORDER_REFLECT_101 (edge pixel not repeated).
        image = F.conv2d(F.pad(image, (2, 2, 2, 2), mode="reflect"), kernel, stride=2)
    return image[:, 0]


def extract_patches(image: torch.Tensor, patch: int, stride: int) -> torch.Tensor:
    """(B,h,w) → (B,P,patch²) patches in row-major order of their position; pixels row-major."""
    windows = image.unfold(1, patch, stride).unfold(2, patch, stride)  # (B, rows, cols, p, p)
    return windows.reshape(image.shape[0], -1, patch * patch)


def scale_patches(gray: torch.Tensor, spec: ScaleSpec) -> torch.Tensor:
    """Raw (un-normalised) patches of one scale: (B,H,W) gray → (B, P_N, patch²)."""
    window = centre_window(gray, spec.window)
    return extract_patches(pyramid_down(window, spec.pyramid_levels), spec.patch, spec.stride)


def zero_mean_unit_norm(vectors: torch.Tensor) -> torch.Tensor:
    """Centre and normalise along the last axis; near-constant vectors become exactly 0 (no NaN)."""
    means = vectors.mean(dim=-1, keepdim=True)
    centred = vectors - means
    norms = torch.linalg.vector_norm(centred, dim=-1, keepdim=True)
    floor = (NEAR_CONSTANT_TOLERANCE * math.sqrt(vectors.shape[-1])) * means.abs()
    return centred * torch.where(norms > floor, norms.reciprocal(), 0.0)


def prepare_reference(raw_reference: torch.Tensor, normalisation: str) -> torch.Tensor:
    """What to cache of I0: normalised halves for ``per_half``; the raw patches for ``joint``."""
    return zero_mean_unit_norm(raw_reference) if normalisation == "per_half" else raw_reference


def stack_pair(
    reference: torch.Tensor, raw_current: torch.Tensor, normalisation: str
) -> torch.Tensor:
    """γ = [I0 half ; I(t) half], (B,P,K); ``reference`` comes from :func:`prepare_reference`."""
    if normalisation == "per_half":
        return torch.cat([reference, zero_mean_unit_norm(raw_current)], dim=-1)
    return zero_mean_unit_norm(torch.cat([reference, raw_current], dim=-1))
