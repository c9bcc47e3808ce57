"""Where does the eye image best match I0? A check of the world behind Tables 2–3 (paper §3.4,
§4.2).

The pursuit policy is rewarded for pans that make I(t) easy to encode together with I0. If the
pixels themselves matched best away from the target pan α* (for instance because the still
background, which has a smaller parallax than the panel, filled part of a window), no learner
could reach the paper's MAE. This module renders each scale's window (grey and
pyramid-subsampled by `parallax.coding.retina`, the coder's configured scales) over a sweep of
pans around α* and reports the pan of the smallest mean squared difference from I0, relative to
α*.

    python -m parallax.tools.analysis.best_match [--distances 3 6.5 10] [--lateral 0.2]
        [--textures 6]
"""

from __future__ import annotations

import argparse

import numpy as np

import parallax.envs
from parallax.coding.retina import ScaleSpec, as_gray_batch, centre_window, pyramid_down
from parallax.config import compose


def scale_specs() -> dict[str, ScaleSpec]:
    """The coder's scales as configured (conf/coder/two_scale.yaml)."""
    specs = compose().coder.scale_specs
    return {name: ScaleSpec.from_mapping(spec) for name, spec in specs.items()}


def window(image: np.ndarray, spec: ScaleSpec) -> np.ndarray:
    """The scale's central window of an RGB eye image, grey and pyramid-subsampled as the retina
    does."""
    # a copy: the task hands out I0 read-only, and torch warns about wrapping such arrays
    gray = centre_window(as_gray_batch(image[None].copy()), spec.window)
    return pyramid_down(gray, spec.pyramid_levels)[0].numpy()


def views_around_target(env, texture: int, distance: float, lateral: float, offsets: np.ndarray):
    """Shows ``texture`` at ``distance``, puts the robot at ``lateral`` and returns (I0, α*,
    frames): the left eye's image at each pan α* + offset (degrees). Shared with
    parallax.tools.analysis.landscape."""
    env.task.set_next_stimulus(texture_index=texture, distance=distance)
    reference = parallax.envs.Observation.of(env.reset().observation).reference
    physics = env.physics
    physics.set_lateral_position(lateral)
    target = physics.target_pan_deg()

    def frames():
        for offset in offsets:
            physics.set_pan_deg(float(target + offset))
            yield physics.render_left_eye()

    return reference, target, frames()


def best_match_offsets(
    distance: float,
    lateral: float,
    textures: int,
    span_deg: float = 1.0,
    step_deg: float = 0.05,
    seed: int = 0,
) -> dict[str, list[float]]:
    """scale → per texture, argmin over pans of MSE(window(I(pan)), window(I0)) minus α*, in
    degrees."""
    env = parallax.envs.load(
        seed=seed, lateral_positions=[lateral], trial_length=30, initial_pan_jitter_deg=0.0
    )
    specs = scale_specs()
    offsets: dict[str, list[float]] = {name: [] for name in specs}
    steps = np.arange(-span_deg, span_deg + step_deg / 2, step_deg)
    try:
        for texture in range(textures):
            reference, target, views = views_around_target(env, texture, distance, lateral, steps)
            frames = list(views)
            pans = target + steps
            for name, spec in specs.items():
                ref = window(reference, spec)
                errors = [float(np.mean((window(f, spec) - ref) ** 2)) for f in frames]
                offsets[name].append(float(pans[int(np.argmin(errors))] - target))
    finally:
        env.close()
    return offsets


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.best_match", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--distances", type=float, nargs="+", default=[3.0, 6.5, 10.0])
    parser.add_argument(
        "--lateral", type=float, default=0.2, help="lateral position, metres (default 0.2)"
    )
    parser.add_argument("--textures", type=int, default=6)
    args = parser.parse_args(argv)
    print(f"best-match pan − α* (deg) at L = {args.lateral * 100:.0f} cm, per texture (step 0.05°)")
    for d in args.distances:
        offsets = best_match_offsets(d, args.lateral, args.textures)
        print(
            f"d = {d:5.2f} m  "
            + "  ".join(
                f"{name}: {np.round(v, 2).tolist()} (mean |·| {np.mean(np.abs(v)):.3f})"
                for name, v in offsets.items()
            )
        )


if __name__ == "__main__":
    main()
