"""Where does the eye image best match I0? A check of the world behind Tables 2–3 (paper §3.4, §4.2).

The pursuit policy is rewarded for pans that make I(t) easy to encode together with I0. If the
pixels themselves matched best away from the target pan α* (for instance because the still
background, which has a smaller parallax than the panel, filled part of a window), no learner
could reach the paper's MAE. This module renders each scale's window (grey, pyramid-subsampled
as in `parallax.coding.retina`) over a sweep of pans around α* and reports the pan of the
smallest mean squared difference from I0, relative to α*.

    python -m parallax.envs.best_match [--distances 3 6.5 10] [--lateral 0.2] [--textures 6]
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

import parallax.envs

#: (window px, subsample) of the paper's coarse and fine scales (conf/coder/two_scale.yaml).
WINDOWS = {"coarse": (250, 8), "fine": (150, 2)}


def window(image: np.ndarray, side: int, subsample: int) -> np.ndarray:
    """The central side×side grey window, pyrDown'ed to 1/subsample."""
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    top = (gray.shape[0] - side) // 2
    left = (gray.shape[1] - side) // 2
    gray = gray[top:top + side, left:left + side]
    while subsample > 1:
        gray = cv2.pyrDown(gray)
        subsample //= 2
    return gray


def best_match_offsets(distance: float, lateral: float, textures: int, span_deg: float = 1.0,
                       step_deg: float = 0.05, seed: int = 0) -> dict[str, list[float]]:
    """scale → per texture, argmin over pans of MSE(window(I(pan)), window(I0)) minus α*, degrees."""
    env = parallax.envs.load(seed=seed, lateral_positions=[lateral], trial_length=30)
    physics = env.physics
    offsets: dict[str, list[float]] = {name: [] for name in WINDOWS}
    try:
        for texture in range(textures):
            env.task.set_next_stimulus(texture_index=texture, distance=distance)
            reference = env.reset().observation["reference"]
            physics.set_lateral_position(lateral)
            target = physics.target_pan_deg()
            pans = target + np.arange(-span_deg, span_deg + step_deg / 2, step_deg)
            frames = []
            for pan in pans:
                physics.set_pan_deg(float(pan))
                frames.append(physics.render_left_eye())
            for name, (side, subsample) in WINDOWS.items():
                ref = window(reference, side, subsample)
                errors = [float(np.mean((window(f, side, subsample) - ref) ** 2)) for f in frames]
                offsets[name].append(float(pans[int(np.argmin(errors))] - target))
    finally:
        env.close()
    return offsets


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m parallax.envs.best_match", description=__doc__.split("\n\n")[0])
    parser.add_argument("--distances", type=float, nargs="+", default=[3.0, 6.5, 10.0])
    parser.add_argument("--lateral", type=float, default=0.2, help="lateral position, metres (default 0.2)")
    parser.add_argument("--textures", type=int, default=6)
    args = parser.parse_args(argv)
    print(f"best-match pan − α* (deg) at L = {args.lateral * 100:.0f} cm, per texture (step 0.05°)")
    for d in args.distances:
        offsets = best_match_offsets(d, args.lateral, args.textures)
        print(f"d = {d:5.2f} m  " + "  ".join(
            f"{name}: {np.round(v, 2).tolist()} (mean |·| {np.mean(np.abs(v)):.3f})" for name, v in offsets.items()))


if __name__ == "__main__":
    main()
