"""The continuous sweep (parallax.envs.sweep, env.motion=continuous): the body really moves in
the simulation while the eye acts, q_p is read as it passes l_p, and bad speeds are refused."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import parallax.envs
from parallax.config import ConfigError, compose, validate
from parallax.envs.sweep import (
    body_offsets,
    fastest_followable_speed_m,
    fastest_target_pan_deg,
    sweep_iterations,
)
from parallax.presentation import Tally


def sweeping_env(speed_m=0.01, profile="constant", lateral=(0.05, 0.1)):
    return parallax.envs.load(
        seed=0,
        lateral_positions=list(lateral),
        image_size=48,
        stimuli={"count": 4},
        motion="continuous",
        sweep={"speed_m": speed_m, "profile": profile},
    )


@pytest.mark.parametrize("profile", ["constant", "smooth"])
def test_the_body_and_its_eye_move_at_every_iteration_of_the_one_trial(profile):
    env = sweeping_env(profile=profile)
    try:
        step = env.reset()
        offsets, bodies, eyes, pans = [], [], [], []
        while True:
            offsets.append(float(step.observation["lateral_position"]))
            bodies.append(env.physics.named.data.xpos["robot"].copy())
            eyes.append(env.physics.named.data.cam_xpos["left_eye"].copy())
            pans.append(float(step.observation["pan"]))
            if step.last():
                break
            step = env.step(0.05)
        assert len(offsets) == env.task.trial_length == sweep_iterations(0.1, 0.01) == 11
        assert offsets[0] == 0.0 and offsets[-1] == pytest.approx(0.1)
        np.testing.assert_allclose(offsets, body_offsets(0.1, 0.01, profile))
        # the simulated body moves sideways (−y) by x(t), and carries the eye's camera along (which
        # the pan also swings a little about the neck)
        bodies, eyes = np.array(bodies), np.array(eyes)
        np.testing.assert_allclose(bodies[0, 1] - bodies[:, 1], offsets, atol=1e-12)
        np.testing.assert_allclose(eyes[0, 1] - eyes[:, 1], offsets, rtol=0.01, atol=1e-4)
        assert np.all(np.diff(offsets[1:-1]) > 0)  # moving at every step but the still ends
        np.testing.assert_allclose(np.diff(pans), 0.05, atol=1e-9)  # while the eye turns
    finally:
        env.close()


def test_the_smooth_profile_starts_and_stops_still_and_peaks_at_1_875_times_the_mean():
    x = body_offsets(0.2, 0.002, "smooth")
    speed = np.diff(x)
    assert x[0] == 0.0 and x[-1] == 0.2 and np.all(speed >= 0)
    assert speed[0] < 0.01 * speed.max() and speed[-1] < 0.01 * speed.max()
    assert speed.max() == pytest.approx(1.875 * 0.002, rel=1e-3)


def test_the_fastest_followable_speed_turns_the_target_by_the_eyes_largest_step():
    for profile in ("constant", "smooth"):
        fastest = fastest_followable_speed_m(0.2, profile, 3.0)
        assert fastest_target_pan_deg(fastest, profile, 3.0) == pytest.approx(0.2)
    assert fastest_followable_speed_m(0.2, "constant", 3.0) == pytest.approx(
        math.radians(0.2) * 3.0
    )


def test_q_p_is_read_between_the_iterations_either_side_of_l_p():
    tally = Tally(robots=1, lateral=[0.05, 0.1], trial_length=3, continuous=True)
    out = SimpleNamespace(reward=torch.zeros(1), errors={})
    for iteration, (x, pan, target) in enumerate(
        [(0.0, 0.0, 0.0), (0.04, 0.5, 0.6), (0.1, 1.1, 1.2)]
    ):
        obs = [SimpleNamespace(iteration=iteration, lateral_position=x, target_pan=target)]
        tally.encoded(obs, out, np.array([pan]), np.zeros(1), 0)
    # l = 0.05 lies 1/6 of the way from 0.04 to 0.1; l = 0.1 is the last iteration's
    np.testing.assert_allclose(tally.pans, [[0.5 + 0.6 / 6, 1.1]])
    np.testing.assert_allclose(tally.targets, [[0.6 + 0.6 / 6, 1.2]])
    motion = tally.sweep.summary()
    assert motion["tracking_error_deg"] == pytest.approx(0.2 / 3)
    assert motion["retinal_slip_deg"] == pytest.approx(0.1 / 2)


def _config(*overrides):
    return compose(
        ["env.motion=continuous", "train.distance_readout=last", "curriculum=multi_5_20"]
        + list(overrides)
    )


def test_a_speed_the_eye_cannot_follow_is_refused_with_the_numbers():
    validate(_config("env.sweep.speed_m=0.01"))  # 0.19° an iteration at 3 m: within 0.2°
    with pytest.raises(ConfigError, match=r"env.sweep.speed_m.*0\.229° .*at most 0\.01047 m"):
        validate(_config("env.sweep.speed_m=0.012"))
    with pytest.raises(ConfigError, match="at most 0.005585 m"):
        validate(_config("env.sweep.speed_m=0.006", "env.sweep.profile=smooth"))


@pytest.mark.parametrize(
    "override, key",
    [
        ("train.distance_readout=best_reward", "train.distance_readout"),
        ("movement.route=planned", "movement.route"),
        ("env.motion=sideways", "env.motion"),
        ("coder.pairing=previous", "coder.pairing"),
        ("env.sweep.speed_m=0", "env.sweep.speed_m"),
    ],
)
def test_settings_a_sweep_cannot_use_are_refused(override, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        validate(_config(override))


def test_a_sweeping_run_logs_the_pursuit_and_reads_every_l_p(tmp_path):
    import json

    from tests.conftest import train_tiny_run

    train_tiny_run(
        tmp_path,
        ["env.motion=continuous", "env.sweep.speed_m=0.01", "train.distance_readout=last"],
    )
    lines = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert all(line["steps"] == 11 * (i + 1) for i, line in enumerate(lines))  # one 11-step sweep
    for line in lines:
        assert np.isfinite(line["pans"]).all() and line["tracking_error_deg"] >= 0
        assert line["retinal_slip_deg"] >= 0
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(tmp_path / "tb"))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert {"motion/tracking_error_deg", "motion/retinal_slip_deg"} <= tags
