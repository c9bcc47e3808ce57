"""`parallax-render`: pictures of the world (paper §4.1, Fig. 1 top; §3.2, Fig. 4).

Writes two PNGs into ``--out``:

- ``scene_side.png`` — the robot, put down at lateral position l, and the panel d metres ahead,
  seen from behind and to the side;
- ``scene_left_eye.png`` — the left eye's view: I0 (l0, pan 0), I at l before any eye movement
  (shifted by the disparity f·l/d, Table 1), and I at l with the pan at α* (fixating again).

Bad input (distance ≤ 0, non-finite values, a texture index out of range) is refused before
anything is written.

``parallax-render RUN --video OUT`` writes a video of a trained run instead
(:mod:`parallax.tools.video`).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np

from parallax.geometry import disparity_score
from parallax.tools import video
from parallax.watch import side_camera

SIDE_SIZE = (800, 480)


def _label(image: np.ndarray, text: str, strip: int = 22) -> np.ndarray:
    """The image with a white caption strip above it."""
    band = np.full((strip, image.shape[1], 3), 255, dtype=np.uint8)
    cv2.putText(
        band, text, (4, strip - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA
    )
    return np.concatenate([band, image], axis=0)


def render_pictures(
    distance_m: float = 3.0,
    lateral_m: float = 0.1,
    seed: int = 0,
    texture_index: int | None = None,
    image_size: int = 256,
) -> dict[str, np.ndarray]:
    """The side view and the left-eye strip as RGB arrays (nothing written)."""
    import parallax.envs
    from parallax.envs import Observation

    if not math.isfinite(lateral_m):
        raise ValueError(f"--lateral must be a finite number of metres, got {lateral_m!r}")
    env = parallax.envs.load(
        seed=seed,
        lateral_positions=[lateral_m],
        trial_length=2,
        distances=[distance_m],
        image_size=image_size,
        initial_pan_jitter_deg=0.0,  # the eye starts at pan 0
    )
    try:
        if texture_index is not None:
            env.task.set_next_stimulus(texture_index=texture_index)
        first = Observation.of(env.reset().observation)
        physics = env.physics
        target = physics.target_pan_deg()
        physics.set_pan_deg(target)
        fixating = physics.render_left_eye()
        side = physics.render_view(side_camera(distance_m, lateral_m), *SIDE_SIZE)
        disparity = disparity_score(lateral_m, distance_m)
        eye = np.concatenate(
            [
                _label(first.reference, "I0 (reference): l = 0, pan 0"),
                np.full((first.image.shape[0] + 22, 6, 3), 255, np.uint8),
                _label(first.image, f"l = {lateral_m * 100:g} cm, pan 0 ({disparity:.1f} px)"),
                np.full((first.image.shape[0] + 22, 6, 3), 255, np.uint8),
                _label(fixating, f"l = {lateral_m * 100:g} cm, pan = target {target:.3f} deg"),
            ],
            axis=1,
        )
        caption = (
            f"d = {distance_m:g} m, l = {lateral_m * 100:g} cm, texture "
            f"{first.texture_index}: {physics.stimuli.names[first.texture_index]}"
        )
        return {"scene_side.png": _label(side, caption), "scene_left_eye.png": eye}
    finally:
        env.close()


def write_pictures(out_dir: str | Path, **options) -> list[Path]:
    """Render, then write the PNGs (only once everything rendered)."""
    pictures = render_pictures(**options)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, rgb in pictures.items():
        path = out / name
        if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {path}")
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="parallax-render", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "run_dir",
        nargs="?",
        default=None,
        help="a run directory, for --video (the pictures need none)",
    )
    parser.add_argument(
        "--out",
        default=".",
        help="folder for the PNGs (default: the working directory; the README's pictures: "
        "--out docs --lateral 0.2 --texture 8)",
    )
    parser.add_argument(
        "--distance",
        type=float,
        nargs="+",
        default=[3.0],
        help="panel distance d in metres (default 3); --video: one presentation per distance",
    )
    parser.add_argument(
        "--lateral", type=float, default=0.1, help="lateral position l in metres (default 0.1)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the texture draw (default 0)")
    parser.add_argument(
        "--texture",
        type=int,
        default=None,
        help="texture index (default: drawn from --seed; --video: held-out photograph 0)",
    )
    parser.add_argument(
        "--image-size", type=int, default=256, help="eye image size in pixels (default 256)"
    )
    video.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.video is not None:
        return video.main(args)
    if args.run_dir is not None:
        parser.error(f"{args.run_dir}: a run directory is for --video OUT only")
    if len(args.distance) != 1:
        parser.error("--distance takes one distance for the pictures (several only with --video)")
    try:
        paths = write_pictures(
            args.out,
            distance_m=args.distance[0],
            lateral_m=args.lateral,
            seed=args.seed,
            texture_index=args.texture,
            image_size=args.image_size,
        )
    except ValueError as error:
        parser.error(str(error))
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
