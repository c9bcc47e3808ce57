"""Speed of the world (paper §3.2: one left-eye image I(t) per iteration), for `parallax-bench`.

Median milliseconds of: one 256×256 left-eye frame alone (``physics.render_left_eye``), one
``env.step`` (turn the eye, render, solve α*, build the observation), one reset (new texture and
distance, I0, first image), the target-pan solver, a blurred frame (§5), the walk to a panel at
10 m and back (the odometry targets' walk, parallax.envs.walk, the farthest of the grid), and
building one more environment; plus the resident memory each extra environment costs. Target:
a frame ≤ 2 ms on a 2-core CPU without GPU.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict

import numpy as np

from parallax.envs.settings import WalkConfig
from parallax.envs.walk import Walker
from parallax.tools.bench.timing import interleaved_medians_ms


def _resident_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def run(repeats: int = 50, image_size: int = 256) -> dict[str, float]:
    """Median milliseconds per operation (and MB per extra environment)."""
    import parallax.envs

    options = dict(
        lateral_positions=[0.05, 0.1, 0.15, 0.2],
        trial_length=30,
        image_size=image_size,
        initial_pan_jitter_deg=0.0,
    )
    env = parallax.envs.load(seed=0, **options)
    env.reset()
    physics = env.physics
    actions = np.random.default_rng(0).choice(parallax.envs.ACTION_SET_DEG, size=repeats + 10)
    action_iter = iter(np.concatenate([actions] * 4))

    def step() -> None:
        if env.step(float(next(action_iter))).last():
            env.reset()

    blurred = parallax.envs.load(seed=0, blur_sigma=2.0, **options)
    blurred.reset()
    far = parallax.envs.load(seed=0, **options)
    far.reset()
    far.physics.set_stimulus(far.physics.texture_index(), 10.0)
    body = asdict(WalkConfig())  # the schema's body (env.walk)
    body.pop("growth_start_fraction")
    walker = Walker(seed=0, **body)
    results = interleaved_medians_ms(
        {
            "render_left_eye_ms": physics.render_left_eye,
            "env_step_ms": step,
            "target_pan_ms": physics.target_pan_deg,
            "render_left_eye_blur2_ms": blurred.physics.render_left_eye,
            "walk_to_10m_ms": lambda: walker.walk(far.physics),
        },
        repeats,
    )
    results.update(
        interleaved_medians_ms({"env_reset_ms": env.reset}, max(5, repeats // 5), warmup=2)
    )
    blurred.close()
    far.close()

    extra, before = [], _resident_mb()
    start = time.perf_counter()
    for seed in range(1, 5):
        extra.append(parallax.envs.load(seed=seed, **options))
        extra[-1].reset()
    results["env_create_and_reset_ms"] = (time.perf_counter() - start) * 1e3 / len(extra)
    results["resident_mb_per_env"] = (_resident_mb() - before) / len(extra)
    for other in extra + [env]:
        other.close()
    results["image_size"] = float(image_size)
    return results


if __name__ == "__main__":
    for name, value in run().items():
        print(f"{name:28s} {value:9.3f}")
