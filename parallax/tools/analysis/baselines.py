"""What the eye-movement MAE of Tables 2–3 (paper §4.2, eq. 16) is worth without any vision.

The target pan α* depends on the lateral position l and on the distance d, which is drawn
uniformly from 3.0, 3.1, …, 10.0 m. An eye that ignores the images can still score well:

- ``pan_zero``: never move (the pan is reset to 0 at each lateral position) — MAE = mean α*;
- ``best_constant``: always go to the same pan for a given l, the median of α* over the grid,
  which minimises the mean absolute error of any distance-blind policy.

A learnt policy has to beat ``best_constant`` to show that its pans carry distance information
at all (the distance learner of §3.5 needs exactly that). α* comes from the world's own
kinematics (`Physics.target_pan_deg`).

    python -m parallax.tools.analysis.baselines [--lateral-cm 5 7 10 13 15 20]
"""

from __future__ import annotations

import argparse

import numpy as np

import parallax.envs
from parallax.tools.evaluate import grid


def target_pans(lateral_m: float, distances: list[float]) -> np.ndarray:
    """α* in degrees at lateral position ``lateral_m`` for each distance (metres)."""
    env = parallax.envs.load(
        seed=0, lateral_positions=[lateral_m], trial_length=2, initial_pan_jitter_deg=0.0
    )
    try:
        pans = []
        for d in distances:
            env.task.set_next_stimulus(distance=d)
            env.reset()
            env.physics.set_lateral_position(lateral_m)
            pans.append(env.physics.target_pan_deg())
        return np.asarray(pans)
    finally:
        env.close()


def constant_pan_baselines(
    laterals_m: list[float], distances: list[float] | None = None
) -> dict[str, dict[str, float]]:
    """Per lateral position (label in cm): MAE of pan 0 and of the best constant pan, degrees."""
    distances = distances or grid(3.0, 10.0, 0.1)
    out = {}
    for lateral in laterals_m:
        alpha = target_pans(lateral, distances)
        best = float(np.median(alpha))
        out[f"{lateral * 100:g}"] = {
            "pan_zero": float(np.abs(alpha).mean()),
            "best_constant": float(np.abs(alpha - best).mean()),
            "best_constant_pan": best,
        }
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.baselines", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--lateral-cm", type=float, nargs="+", default=[5, 7, 10, 13, 15, 20])
    args = parser.parse_args(argv)
    baselines = constant_pan_baselines([l / 100 for l in args.lateral_cm])
    print("| L (cm) | MAE, pan stays 0 (deg) | MAE, best constant pan (deg) | that pan (deg) |")
    print("|---|---|---|---|")
    for label, b in baselines.items():
        print(
            f"| {label} | {b['pan_zero']:.3f} | {b['best_constant']:.3f} | "
            f"{b['best_constant_pan']:.3f} |"
        )


if __name__ == "__main__":
    main()
