"""The world (parallax.envs): geometry, target pan, episode structure, perturbations, API."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

import parallax.envs
from parallax.envs import hoap3
from parallax.geometry import FOCAL_LENGTH_PX, disparity_score

TABLE_1 = {0.05: 9, 0.07: 12, 0.10: 18, 0.13: 23, 0.15: 27, 0.20: 35}
SMALL_STIMULI = {"count": 6}


def small_env(seed=0, **options):
    settings = dict(
        lateral_positions=[0.05, 0.1],
        trial_length=3,
        image_size=48,
        stimuli=SMALL_STIMULI,
        initial_pan_jitter_deg=0.0,
    )
    settings.update(options)
    return parallax.envs.load(seed=seed, **settings)


@pytest.fixture(scope="module")
def eye_env():
    """A full-size (256 px) world for measurements in the image."""
    env = parallax.envs.load(
        seed=0,
        lateral_positions=[0.05],
        image_size=256,
        stimuli=SMALL_STIMULI,
        initial_pan_jitter_deg=0.0,
    )
    env.reset()
    yield env
    env.close()


def marker_centre(physics: hoap3.Physics, radius_px: float = 9.0) -> np.ndarray:
    """Sub-pixel (column, row) of the disc drawn at the panel centre, found in the rendered
    image."""
    marker = physics.model.name2id("fixation_marker", "geom")
    physics.model.geom_size[marker, 0] = radius_px * physics.distance() / FOCAL_LENGTH_PX
    with_marker = physics.render_left_eye(show_marker=True).astype(int)
    without = physics.render_left_eye().astype(int)
    mask = np.abs(with_marker - without).sum(axis=2) > 30
    assert mask.sum() > 0.7 * math.pi * radius_px**2, "the marker is not in view"
    rows, cols = np.nonzero(mask)
    return np.array([cols.mean(), rows.mean()])


# --- robot, camera and geometry -----------------------------------------------------------------
def test_robot_has_hoap3_proportions(eye_env):
    physics = eye_env.physics
    physics.set_lateral_position(0.0)
    physics.set_pan_deg(0.0)
    named = physics.named.data
    pan_axis = named.xanchor["head_pan"]
    assert pan_axis == pytest.approx([0.0, 0.0, 0.5])
    assert named.xanchor["head_tilt"] - pan_axis == pytest.approx([0.015, 0.0, 0.103])
    left, right = named.cam_xpos["left_eye"], named.cam_xpos["right_eye"]
    assert left == pytest.approx([0.065, 0.03, 0.607]) and right == pytest.approx(
        [0.065, -0.03, 0.607]
    )
    assert left == pytest.approx([hoap3.EYE_FORWARD_M, hoap3.EYE_LEFT_M, hoap3.EYE_HEIGHT_M])
    tops = [physics.named.data.geom_xpos[name][2] for name in ("skull", "foot_left")]
    assert 0.58 < tops[0] + physics.named.model.geom_size["skull"][2] < 0.66  # about 0.60 m tall
    assert tops[1] - physics.named.model.geom_size["foot_left"][2] == pytest.approx(0.0, abs=1e-9)
    assert physics.named.model.jnt_range["head_pan"] == pytest.approx(np.radians([-60, 60]))


# --- camera and geometry ---------------------------------------------------------------------
@pytest.mark.parametrize("size", [48, 250, 256, 512])
def test_focal_length_is_531_px_for_every_image_size(size):
    fovy = math.radians(hoap3.eye_fovy_deg(size))
    assert (size / 2) / math.tan(fovy / 2) == pytest.approx(FOCAL_LENGTH_PX, rel=1e-12)


def test_disparity_score_reproduces_table_1():
    for lateral, score in TABLE_1.items():
        assert round(disparity_score(lateral, 3.0)) == score


def test_rendered_disparity_at_3m_is_table_1(eye_env):
    """The panel centre moves by f·l/d pixels when the body is put down at l with the pan at 0."""
    physics = eye_env.physics
    physics.set_stimulus(0, 3.0)
    physics.set_pan_deg(0.0)
    physics.set_lateral_position(0.0)
    origin = marker_centre(physics)
    assert origin == pytest.approx([127.5, 127.5], abs=0.5)
    for lateral, score in TABLE_1.items():
        physics.set_lateral_position(lateral)
        shift = origin[0] - marker_centre(physics)[0]
        assert shift == pytest.approx(disparity_score(lateral, 3.0), abs=0.5)
        assert round(shift) == score


@pytest.mark.parametrize(
    "distance,lateral",
    [(3.0, 0.20), (10.0, 0.05), (3.0, 0.05), (10.0, 0.20), (6.4, 0.13), (4.2, -0.07)],
)
def test_target_pan_puts_panel_centre_in_image_centre(eye_env, distance, lateral):
    physics = eye_env.physics
    physics.set_stimulus(1, distance)
    physics.set_lateral_position(lateral)
    target = physics.target_pan_deg()
    physics.set_pan_deg(target)
    assert np.abs(marker_centre(physics) - 127.5).max() < 0.5
    assert np.abs(physics.project_to_left_eye(physics.panel_centre()) - 127.5).max() < 1e-6
    # The pan axis is 0.065 m behind the eye: α* ≈ atan(l/(d + 0.065)), smaller than atan(l/d).
    assert target == pytest.approx(math.degrees(math.atan(lateral / (distance + 0.065))), abs=2e-3)
    assert abs(target) < abs(math.degrees(math.atan(lateral / distance)))
    physics.set_pan_deg(0.0)


def test_target_pan_is_zero_at_l0(eye_env):
    physics = eye_env.physics
    for distance in (3.0, 7.3, 10.0):
        physics.set_stimulus(0, distance)
        physics.set_lateral_position(0.0)
        assert physics.target_pan_deg() == pytest.approx(0.0, abs=1e-9)


def test_eye_sees_the_texture_upright_and_unmirrored(eye_env):
    physics = eye_env.physics
    physics.set_stimulus(2, 10.0)
    physics.set_lateral_position(0.0)
    physics.set_pan_deg(0.0)
    image = cv2.cvtColor(physics.render_left_eye(), cv2.COLOR_RGB2GRAY).astype(float)
    half_panel_px = FOCAL_LENGTH_PX * hoap3.PANEL_SIDE_M / 2 / 10.0
    view = image[128 - 80 : 128 + 80, 128 - 80 : 128 + 80]
    texture = cv2.cvtColor(
        np.ascontiguousarray(physics.stimuli.textures[2]), cv2.COLOR_RGB2GRAY
    ).astype(float)
    side = texture.shape[0]
    inner = int(round(side / 2 * 80 / half_panel_px))
    texture = texture[side // 2 - inner : side // 2 + inner, side // 2 - inner : side // 2 + inner]

    def correlation(a, b):
        a, b = cv2.resize(a, (40, 40)).ravel(), cv2.resize(b, (40, 40)).ravel()
        return np.corrcoef(a, b)[0, 1]

    upright = correlation(view, texture)
    assert upright > 0.9
    assert upright > correlation(view, texture[::-1]) + 0.1
    assert upright > correlation(view, texture[:, ::-1]) + 0.1


def test_panel_covers_fine_window_at_10m_and_swaps_texture_without_recompiling(eye_env):
    physics = eye_env.physics
    model = physics.model.ptr
    physics.set_lateral_position(0.2)
    physics.set_pan_deg(0.0)
    frames = []
    for texture in range(4):
        physics.set_stimulus(texture, 10.0)
        frames.append(physics.render_left_eye().astype(int))
    assert physics.model.ptr is model
    changes = np.zeros(frames[0].shape[:2], dtype=bool)
    for frame in frames[1:]:
        changes |= np.abs(frame - frames[0]).sum(axis=2) > 0
    assert changes[128 - 75 : 128 + 75, 128 - 75 : 128 + 75].all(), (
        "the fine window sees past the panel"
    )
    assert not changes[:20, :20].any(), "the background should not change with the texture"


def test_pan_accessor_clips_to_limits(eye_env):
    physics = eye_env.physics
    assert physics.set_pan_deg(75.0) == 60.0 and physics.pan_deg() == pytest.approx(60.0)
    assert physics.set_pan_deg(-61.0) == -60.0
    physics.set_pan_deg(0.0)


# --- episode structure -------------------------------------------------------------------------
def test_episode_has_r_times_th_observations_and_qp_at_last_iteration():
    env = small_env(lateral_positions=[0.05, 0.1, 0.15], trial_length=4)
    step = env.reset()
    reference = step.observation["reference"]
    increments = [0.2, -0.05, 0.1, 0.05, 0.2, 0.2, -0.1]
    seen, expected_pan, k = [], 0.0, 0
    while True:
        obs = step.observation
        seen.append((int(obs["position_index"]), int(obs["iteration"])))
        assert obs["reference"] is reference
        assert obs["lateral_position"] == pytest.approx([0.05, 0.1, 0.15][obs["position_index"]])
        if obs["iteration"] == 0:
            expected_pan = 0.0  # pan reset at each new position
        assert obs["pan"] == pytest.approx(expected_pan)
        if step.last():
            break
        increment = increments[k % len(increments)]
        step = env.step(increment)
        expected_pan += increment
        k += 1
        assert step.discount == 1.0
        assert step.reward == pytest.approx(
            -abs(step.observation["pan"] - step.observation["target_pan"])
        )
    assert seen == [(p, t) for p in range(3) for t in range(4)]
    assert env.step(0.0).first()
    env.close()


def test_pan_accumulates_increments_and_is_kept_when_asked():
    env = small_env(trial_length=3, pan_reset=False)
    env.reset()
    pans = [float(env.step(a).observation["pan"]) for a in (0.2, 0.1, 0.05, -0.1)]
    # iterations 1, 2, then the move to l2 (the increment still applies, the pan is kept), then 1.
    assert pans == pytest.approx([0.2, 0.3, 0.35, 0.25])
    env.close()
    env = small_env(trial_length=3, pan_reset=True)
    env.reset()
    pans = [float(env.step(a).observation["pan"]) for a in (0.2, 0.1, 0.05, -0.1)]
    assert pans == pytest.approx([0.2, 0.3, 0.0, -0.1])
    env.close()


def test_trials_can_start_from_a_jittered_pan_without_touching_the_reference():
    env = small_env(trial_length=2, initial_pan_jitter_deg=0.5)
    starts = []
    for _ in range(4):
        first = env.reset().observation
        starts.append(float(first["pan"]))
        env.step(0.0)
        starts.append(float(env.step(0.0).observation["pan"]))  # the second trial's start
        env.step(0.0)
    assert all(-0.5 <= p <= 0.5 for p in starts) and len(set(starts)) == len(starts)
    physics = env.physics
    physics.set_lateral_position(0.0)
    physics.set_pan_deg(0.0)
    assert np.array_equal(first["reference"], physics.render_left_eye())  # I0 is still at pan 0
    env.close()
    # no jitter draws nothing: the same textures and distances as before the option existed
    plain, zero = small_env(), small_env(initial_pan_jitter_deg=0.0)
    for _ in range(3):
        a, b = plain.reset().observation, zero.reset().observation
        assert (a["texture_index"], a["distance"], a["pan"]) == (
            b["texture_index"],
            b["distance"],
            0.0,
        )
    plain.close()
    zero.close()


def test_the_start_jitter_can_be_switched_off_and_on():
    env = small_env(trial_length=2, initial_pan_jitter_deg=0.5)
    assert env.task.start_jitter_enabled
    env.task.set_start_jitter(False)
    assert float(env.reset().observation["pan"]) == 0.0  # the paper's start
    env.task.set_start_jitter(True)
    assert float(env.reset().observation["pan"]) != 0.0
    with pytest.raises(ValueError, match="start jitter must be True or False, got 'no'"):
        env.task.set_start_jitter("no")
    env.close()


def test_reference_is_the_l0_image_with_pan_zero():
    env = small_env()
    first = env.reset().observation
    physics = env.physics
    physics.set_lateral_position(0.0)
    physics.set_pan_deg(0.0)
    assert np.array_equal(first["reference"], physics.render_left_eye())
    assert not first["reference"].flags.writeable
    env.close()


def test_same_seed_same_observations_other_seed_other_sequence():
    def run(seed):
        env = small_env(seed=seed, distances={"start": 3.0, "stop": 10.0, "step": 0.1})
        out = []
        for _ in range(4):
            step = env.reset()
            out.append(
                (
                    int(step.observation["texture_index"]),
                    float(step.observation["distance"]),
                    step.observation["reference"].copy(),
                    env.step(0.1).observation["image"].copy(),
                )
            )
        env.close()
        return out

    first, again, other = run(3), run(3), run(4)
    for a, b in zip(first, again):
        assert a[:2] == b[:2] and np.array_equal(a[2], b[2]) and np.array_equal(a[3], b[3])
    assert [a[:2] for a in first] != [c[:2] for c in other]


def test_forced_stimulus_applies_once_and_keeps_the_random_sequence():
    forced, plain = small_env(seed=5), small_env(seed=5)
    forced.task.set_next_stimulus(texture_index=4, distance=4.25)
    obs = forced.reset().observation
    assert (int(obs["texture_index"]), float(obs["distance"])) == (4, 4.25)
    plain.reset()
    for _ in range(3):
        a, b = forced.reset().observation, plain.reset().observation
        assert (a["texture_index"], a["distance"]) == (b["texture_index"], b["distance"])
    forced.close()
    plain.close()


def test_set_lateral_positions_takes_effect_at_next_reset():
    env = small_env(lateral_positions=[0.05, 0.1])
    env.reset()
    env.task.set_lateral_positions([0.07])
    assert env.task.lateral_positions == (0.07,)
    assert env.task.episode_lateral_positions == (0.05, 0.1)
    assert env.step(0.0).observation["lateral_position"] == pytest.approx(0.05)
    assert env.reset().observation["lateral_position"] == pytest.approx(0.07)
    env.close()


def test_distance_grid_is_the_papers_by_default():
    grid = parallax.envs.distance_grid(None)
    assert len(grid) == 71 and grid[0] == 3.0 and grid[-1] == 10.0 and grid[1] == pytest.approx(3.1)
    assert parallax.envs.distance_grid([3.0, 5.5]) == (3.0, 5.5)


# --- perturbations (§5) -------------------------------------------------------------------------
def test_blur_and_rotation_switch_on_mid_run_without_recompiling():
    env = small_env(image_size=96)
    env.task.set_next_stimulus(texture_index=0, distance=3.0)
    env.reset()
    physics = env.physics
    model = physics.model.ptr
    sharp = physics.render_left_eye()
    target = physics.target_pan_deg()

    env.task.set_perturbation(blur_sigma=2.0)
    assert np.array_equal(physics.render_left_eye(), cv2.GaussianBlur(sharp, (0, 0), 2.0))
    env.task.set_perturbation(blur_sigma=0.0, camera_rotation_deg=15.0)
    rotated = physics.render_left_eye().astype(float)
    assert physics.model.ptr is model
    assert physics.target_pan_deg() == pytest.approx(target, abs=1e-9)  # about the optical axis

    centre = ((96 - 1) / 2, (96 - 1) / 2)
    inner = slice(28, 68)

    def match(angle):
        warped = cv2.warpAffine(
            sharp, cv2.getRotationMatrix2D(centre, angle, 1.0), (96, 96), flags=cv2.INTER_LINEAR
        ).astype(float)
        return np.abs(warped[inner, inner] - rotated[inner, inner]).mean()

    # A positive rotation turns the camera clockwise about its line of sight (seen from behind it):
    # the view turns 15° counter-clockwise about the image centre (cv2's positive sense).
    best = match(15.0)
    assert best < 0.5 * match(0.0)
    assert best < min(match(-15.0), match(10.0), match(20.0))

    step = env.step(0.0)
    assert np.array_equal(step.observation["image"], physics.render_left_eye())
    env.task.set_perturbation(camera_rotation_deg=0.0)
    assert np.array_equal(
        physics.render_left_eye(), sharp
    )  # a zero increment left the view as it was
    env.close()


def test_rotation_about_the_vertical_axis_moves_the_target_pan():
    env = small_env(rotation_axis="vertical", camera_rotation_deg=15.0)
    env.reset()
    rotated_target = env.physics.target_pan_deg()
    env.task.set_perturbation(camera_rotation_deg=0.0)
    assert abs(rotated_target - env.physics.target_pan_deg()) == pytest.approx(15.0, abs=0.5)
    env.close()


# --- bad input ------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "options,named",
    [
        ({"distances": [3.0, 0.0]}, "0.0"),
        ({"distances": [-2.0]}, "-2.0"),
        ({"distances": [float("nan")]}, "nan"),
        ({"distances": [float("inf")]}, "inf"),
        ({"distances": []}, "[]"),
        ({"lateral_positions": []}, "[]"),
        ({"lateral_positions": [0.1, 0.05]}, "0.05"),
        ({"lateral_positions": [0.1, 0.1]}, "0.1"),
        ({"lateral_positions": [0.05, float("nan")]}, "nan"),
    ],
)
def test_bad_options_are_refused_with_the_value_named(options, named):
    # lists of distances and positions, which a route also gives at run time; the settings'
    # ranges are parallax.config's (tests/config/test_bad_input.py)
    with pytest.raises(ValueError, match=None) as error:
        small_env(**options)
    assert named in str(error.value)


def test_bad_runtime_values_are_refused():
    env = small_env()
    env.reset()
    with pytest.raises(ValueError, match="99"):
        env.task.set_next_stimulus(texture_index=99)
    with pytest.raises(ValueError, match="-1"):
        env.physics.set_stimulus(-1, 3.0)
    with pytest.raises(ValueError, match="0"):
        env.task.set_next_stimulus(distance=0.0)
    with pytest.raises(ValueError, match=r"\[0.2, 0.1\]"):
        env.task.set_lateral_positions([0.2, 0.1])
    with pytest.raises(ValueError, match="0.5"):
        env.step(0.5)
    with pytest.raises(ValueError, match="nan"):
        env.step(float("nan"))
    assert env.task.lateral_positions == (0.05, 0.1)
    env.close()


# --- several environments in one process ------------------------------------------------------
def test_sixteen_environments_render_in_one_process():
    envs = [small_env(seed=seed) for seed in range(16)]
    firsts = [env.reset().observation for env in envs]
    assert len({id(env.physics.stimuli) for env in envs}) == 1  # textures decoded once, shared
    for _ in range(2):
        steps = [env.step(0.1) for env in envs]
    for env, _first, step in zip(envs, firsts, steps):
        image = step.observation["image"]
        assert image.shape == (48, 48, 3) and image.std() > 1
        # Interleaved rendering gives each world its own view.
        assert np.array_equal(image, env.physics.render_left_eye())
    distinct = {(int(f["texture_index"]), float(f["distance"])) for f in firsts}
    assert len(distinct) > 8
    for env in envs:
        env.close()


@pytest.mark.slow
def test_a_paper_sized_presentation_with_sixteen_full_size_robots():
    """L = 5…20 cm, t_h = 30, 256 px: 480 observations per robot, q_p at every 30th."""
    lateral = [round(0.05 + 0.01 * k, 2) for k in range(16)]
    envs = [
        parallax.envs.load(seed=seed, lateral_positions=lateral, initial_pan_jitter_deg=0.0)
        for seed in range(16)
    ]
    steps = [env.reset() for env in envs]
    count, finals = 1, []
    while not steps[0].last():
        steps = [env.step(0.1) for env in envs]
        count += 1
        if steps[0].observation["iteration"] == 29:
            finals.append(float(steps[0].observation["pan"]))
    assert count == 16 * 30 and all(step.last() for step in steps)
    assert finals == pytest.approx([2.9] * 16)
    for env in envs:
        env.close()


def test_the_pixels_match_i0_best_at_the_target_pan():
    """The world itself puts the best image match at α* (so the pursuit MAE is the learner's)."""
    from parallax.tools.analysis.best_match import best_match_offsets

    offsets = best_match_offsets(
        distance=10.0, lateral=0.2, textures=2, span_deg=0.5, step_deg=0.05
    )
    assert all(abs(v) <= 0.1 for values in offsets.values() for v in values), offsets


def test_a_fovea_render_is_the_full_render_at_its_centre_and_coarser_around_it():
    """env.fovea_px: the central square is the full render's pixels (to one level: the narrower
    camera samples the texture with other rounding), the rest the periphery's 4×4 blocks, and
    the image keeps its size."""
    full = parallax.envs.load(seed=3)
    foveal = parallax.envs.load(seed=3, fovea_px=150)
    try:
        for step in (lambda env: env.reset(), lambda env: env.step(0.1)):
            whole, parts = (step(env).observation["image"] for env in (full, foveal))
            assert parts.shape == whole.shape == (256, 256, 3)
            centre = parts[53:203, 53:203].astype(int) - whole[53:203, 53:203]
            assert np.abs(centre).max() <= 1 and np.mean(centre != 0) < 0.01
            corner = parts[:52, :52].reshape(13, 4, 13, 4, 3)
            assert (corner == corner[:, :1, :, :1]).all()
            assert not np.array_equal(parts[:52, :52], whole[:52, :52])
    finally:
        full.close()
        foveal.close()
