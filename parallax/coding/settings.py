"""The sensory coder's settings (coder.*; paper §3.3, eqs. 1–6) beside their checks.

Every setting of the coder as a typed dataclass field with its one default, the choices it
allows, and the checks of the values a type cannot rule out (parallax.checks).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from parallax.checks import ROBOT_UPDATES, Checks

#: coder.normalisation: each eye's half of a patch pair zero-mean and unit-norm (§3.3), or the
#: pair as one vector.
NORMALISATIONS = ("per_half", "joint")
#: coder.pairing: the paper's (I0, I(t)), or consecutive images (I(t−1), I(t)).
PAIRINGS = ("reference", "consecutive")


@dataclass
class ScaleSpecConfig:
    """One scale of §3.3 / Fig. 5: centre window, Gaussian-pyramid sub-sampling P_s, patch side
    P_l and the patches' stride, all in pixels."""

    #: Side of the centre window cut from the eye image (px).
    window: int = MISSING
    #: P_s, the Gaussian pyramid's sub-sampling factor of the window.
    subsample: int = MISSING
    #: P_l, the side of a square patch of the sub-sampled window (px).
    patch: int = MISSING
    #: Step between neighbouring patches (px of the sub-sampled window).
    stride: int = MISSING


def _paper_scales() -> dict[str, ScaleSpecConfig]:
    # §3.3: coarse 250 px sub-sampled ×8 (32×32 px → 529 patches at stride 1), fine 150 px
    # sub-sampled ×2 (75×75 px → 289 patches at stride 4); 10×10 px patches
    return {
        "coarse": ScaleSpecConfig(window=250, subsample=8, patch=10, stride=1),
        "fine": ScaleSpecConfig(window=150, subsample=2, patch=10, stride=4),
    }


@dataclass
class CoderConfig:
    """Sensory coding (§3.3, eqs. 1–6): matching pursuit on a learned binocular dictionary per
    scale; the state θ = [θ^C; θ^F] (eq. 5) and the reward R = −(e^C + e^F) (eq. 6)."""

    _target_: str = "parallax.coding.MultiScaleCoder"
    #: The scales in use, in this order in the state; [coarse] or [fine] is the single-scale
    #: ablation (§3.3 and its reference [4]).
    scales: list[str] = field(default_factory=lambda: ["coarse", "fine"])
    scale_specs: dict[str, ScaleSpecConfig] = field(default_factory=_paper_scales)
    #: N, basis functions per scale (§3.3).
    atoms: int = 288
    #: k, matching-pursuit steps: non-zero coefficients per patch (§3.3).
    sparsity: int = 10
    #: η of the dictionaries' gradient step on the reconstruction error (§3.3, after eq. 4; the
    #: paper gives no value): ΔΦ = η·R·Bᵀ/P.
    learning_rate: float = 0.01
    #: per_half: each eye's half of γ zero-mean and unit-norm (§3.3) | joint: the 200-vector.
    normalisation: str = "per_half"
    #: false freezes the dictionaries.
    learn: bool = True
    #: The image pairs coded: reference, (I0, I(t)) (§3.2) | consecutive, (I(t−1), I(t)), the
    #: retinal slip (beyond the paper; I(−1) is I0).
    pairing: str = "reference"
    #: B robots in lockstep (ROBOT_UPDATES): each (beyond the paper: the sum of every robot's own
    #: step, so every robot's patches teach in full) | mean (one step on the mean over all their
    #: patches, so B robots teach the dictionaries as much as one).
    robot_updates: str = "each"
    #: Filled by the trainer: the dictionaries' initialisation seed.
    seed: int = MISSING
    #: Filled by the trainer: env.image_size.
    image_size: int = MISSING


def check(check: Checks) -> None:
    scales = check.get("coder.scales")
    specs = check.get("coder.scale_specs") or {}
    if not scales:
        check.fail("coder.scales", scales, "needs at least one scale")
    if len(set(scales)) != len(scales):
        check.fail("coder.scales", scales, "must not name a scale twice")
    for name in scales:
        if name not in specs:
            check.fail("coder.scales", scales, f"{name!r} has no coder.scale_specs entry")
    image_size = int(check.get("env.image_size"))
    for name in scales:
        key = f"coder.scale_specs.{name}"
        window = check.integer(f"{key}.window", 1, " (pixels)")
        subsample = check.integer(f"{key}.subsample", 1)
        patch = check.integer(f"{key}.patch", 1, " (pixels)")
        check.integer(f"{key}.stride", 1, " (pixels)")
        if subsample & (subsample - 1):
            check.fail(f"{key}.subsample", subsample, "must be a power of 2 (Gaussian pyramid)")
        if window > image_size:
            check.fail(f"{key}.window", window, f"is larger than env.image_size={image_size}")
        side = window
        for _ in range(subsample.bit_length() - 1):
            side = (side + 1) // 2  # the pyramid's pyrDown maps n px to ⌈n/2⌉
        if side < patch:
            check.fail(
                f"{key}.window",
                window,
                f"sub-sampled ×{subsample} gives {side} px, fewer than the patch side {patch}",
            )
    check.integer("coder.atoms", 1, " (basis functions)")
    check.integer("coder.sparsity", 1, " (matching-pursuit steps)")
    check.number("coder.learning_rate", at_least=0)
    check.choice("coder.normalisation", NORMALISATIONS)
    check.choice("coder.robot_updates", ROBOT_UPDATES)
    check.choice("coder.pairing", PAIRINGS)
