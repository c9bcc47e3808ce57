"""The world's outside: dm_env conformance, the shipped config, headless backends, picture,
benchmark."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import dm_env
import numpy as np
import pytest
from absl.testing import absltest
from dm_env import test_utils
from omegaconf import OmegaConf

import parallax.envs
from parallax.config import compose
from parallax.tools import render as picture
from parallax.tools.bench import envs as benchmark

REPO = Path(__file__).resolve().parents[2]


class ConformanceTest(test_utils.EnvironmentTestMixin, absltest.TestCase):
    """dm_env's own conformance suite, over several whole episodes."""

    def make_object_under_test(self):
        return parallax.envs.load(
            seed=1,
            initial_pan_jitter_deg=0.0,
            lateral_positions=[0.05, 0.1],
            trial_length=3,
            image_size=32,
            stimuli={"count": 4},
        )

    def make_action_sequence(self):
        actions = parallax.envs.ACTION_SET_DEG
        for k in range(15):  # 2.5 episodes of 6 observations
            yield np.float64(actions[k % len(actions)])


def test_environment_is_a_dm_control_environment():
    from dm_control.rl import control

    env = parallax.envs.load(
        seed=0,
        lateral_positions=[0.05],
        image_size=32,
        stimuli={"count": 2},
        initial_pan_jitter_deg=0,
    )
    assert isinstance(env, control.Environment) and isinstance(env, dm_env.Environment)
    spec = env.action_spec()
    assert spec.shape == () and spec.minimum == -0.2 and spec.maximum == 0.2
    assert set(env.observation_spec()) == {
        "reference",
        "image",
        "pan",
        "target_pan",
        "distance",
        "lateral_position",
        "position_index",
        "iteration",
        "texture_index",
    }
    env.close()


def test_shipped_config_maps_onto_load():
    cfg = OmegaConf.create(OmegaConf.to_container(compose().env))  # conf/env/hoap3.yaml
    kwargs = OmegaConf.to_container(cfg, resolve=True)
    # `robots` and `robots_per_turn` are the experiment's (how many environments to make, and
    # the order of their turns) and `walk` the body's walk (parallax.envs.walk): not arguments
    # of load().
    assert kwargs.pop("robots") == 1
    assert kwargs.pop("robots_per_turn") == 4
    assert kwargs.pop("walk")["growth_start_fraction"] is None
    assert (
        kwargs["image_size"] == 256 and kwargs["trial_length"] == 30 and kwargs["pan_reset"] is True
    )
    assert parallax.envs.distance_grid(kwargs["distances"]) == parallax.envs.distance_grid(None)
    kwargs.update(image_size=32, trial_length=2)
    kwargs["stimuli"]["count"] = 3
    env = parallax.envs.load(seed=0, lateral_positions=[0.05, 0.06], **kwargs)
    step = env.reset()
    assert step.observation["image"].shape == (32, 32, 3)
    assert env.task.num_textures == 3
    env.close()
    # DictConfig / ListConfig values (not converted) work too.
    cfg.image_size, cfg.trial_length, cfg.stimuli.count = 32, 2, 3
    del cfg["robots"], cfg["robots_per_turn"], cfg["walk"]
    env = parallax.envs.load(seed=0, lateral_positions=[0.05], **cfg)
    assert env.reset().observation["distance"] >= 3.0
    env.close()


def _run_python(code: str, gl: str | None) -> subprocess.CompletedProcess:
    environment = {
        k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")
    }
    if gl is not None:
        environment["MUJOCO_GL"] = gl
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=environment, timeout=120
    )


RENDER_ONE = """
import os, parallax.envs
env = parallax.envs.load(seed=0, lateral_positions=[0.05], image_size=16, stimuli={"count": 1},
                         initial_pan_jitter_deg=0)
print(os.environ["MUJOCO_GL"], env.reset().observation["image"].shape)
"""


def test_mujoco_gl_defaults_to_egl_and_renders():
    result = _run_python(RENDER_ONE, gl=None)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split()[0] == "egl"


def test_a_backend_the_user_chose_is_respected_or_named_in_one_clear_error():
    result = _run_python(RENDER_ONE, gl="osmesa")
    if result.returncode == 0:
        assert result.stdout.split()[0] == "osmesa"
    else:
        last = result.stderr.strip().splitlines()[-1]
        assert last.startswith("RuntimeError: MUJOCO_GL=osmesa") and "install" in last


def test_picture_command_writes_both_views(tmp_path):
    out = tmp_path / "pictures"
    assert (
        picture.main(
            ["--out", str(out), "--distance", "4", "--lateral", "0.1", "--image-size", "64"]
        )
        == 0
    )
    side = cv2.imread(str(out / "scene_side.png"))
    eye = cv2.imread(str(out / "scene_left_eye.png"))
    assert side.shape[1] == picture.SIDE_SIZE[0] and side.std() > 10
    assert eye.shape[1] == 3 * 64 + 2 * 6 and eye.std() > 10


@pytest.mark.parametrize(
    "argv",
    [["--distance", "0"], ["--distance", "nan"], ["--lateral", "inf"], ["--texture", "100000"]],
)
def test_picture_command_refuses_bad_input_and_writes_nothing(tmp_path, argv):
    out = tmp_path / "pictures"
    with pytest.raises(SystemExit) as exit_info:
        picture.main(["--out", str(out), "--image-size", "32", *argv])
    assert exit_info.value.code == 2
    assert not out.exists()


def test_benchmark_reports_medians():
    results = benchmark.run(repeats=3, image_size=32)
    for key in (
        "render_left_eye_ms",
        "env_step_ms",
        "env_reset_ms",
        "target_pan_ms",
        "resident_mb_per_env",
    ):
        assert key in results and np.isfinite(results[key])
    assert results["render_left_eye_ms"] > 0
