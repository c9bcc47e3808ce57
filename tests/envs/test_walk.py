"""The body's walk to the panel (parallax.envs.walk): the touch is MuJoCo's hand–panel distance
(moving the panel, the hand or the panel's geom in the model changes the count; the scene's
distance attribute is never read), the body is put back exactly, slip-free walks are exact to
one substep, slip is seeded, a growth spurt shortens the count, and bad arguments are refused."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

import parallax.envs
from parallax.envs.walk import HAND_GEOM, PANEL_GEOM, Walker, walk_robots

STRIDE_M = 0.05
SUBSTEPS = 10


@pytest.fixture(scope="module")
def physics():
    env = parallax.envs.load(
        seed=0,
        initial_pan_jitter_deg=0.0,
        lateral_positions=[0.05, 0.1],
        image_size=64,
        stimuli={"count": 2},
    )
    env.reset()
    yield env.physics
    env.close()


@pytest.fixture
def at_3m(physics):
    """The panel 3 m ahead of the eye for the test, then back where the reset put it."""
    texture, distance = physics.texture_index(), physics.distance()
    physics.set_stimulus(texture, 3.0)
    yield physics
    physics.set_stimulus(texture, distance)


def walker(seed=0, **options) -> Walker:
    settings = dict(
        stride_m=STRIDE_M, stride_slip=0.0, substeps=SUBSTEPS, growth_factor=1.0, seed=seed
    )
    settings.update(options)
    return Walker(**settings)


@contextlib.contextmanager
def changed_model(physics, field: str, geom: str, value):
    """``model.<field>[geom]`` set to ``value`` for the block, then restored (and kinematics
    recomputed either way)."""
    array = getattr(physics.model, field)
    index = physics.model.name2id(geom, "geom")
    old = np.array(array[index], copy=True)
    array[index] = value
    physics.forward()
    try:
        yield
    finally:
        array[index] = old
        physics.forward()


def _body_state(physics) -> dict[str, np.ndarray]:
    data = physics.data
    return {
        "mocap_pos": np.array(data.mocap_pos, copy=True),
        "mocap_quat": np.array(data.mocap_quat, copy=True),
        "qpos": np.array(data.qpos, copy=True),
        "xpos": np.array(data.xpos, copy=True),
        "geom_xpos": np.array(data.geom_xpos, copy=True),
        "cam_xpos": np.array(data.cam_xpos, copy=True),
    }


# -- the touch is MuJoCo's ------------------------------------------------------------------------
def test_the_gap_is_the_panel_plane_minus_the_hand_sphere(at_3m):
    physics = at_3m
    hand = physics.model.name2id(HAND_GEOM, "geom")
    panel = physics.model.name2id(PANEL_GEOM, "geom")
    radius = float(physics.model.geom_size[hand][0])
    expected = physics.data.geom_xpos[panel][0] - physics.data.geom_xpos[hand][0] - radius
    assert Walker.gap_m(physics) == pytest.approx(expected, abs=1e-9)
    assert 2.9 < Walker.gap_m(physics) < 3.0  # the hand reaches a little beyond the eye


@pytest.mark.parametrize("d_far", [3.3, 4.25, 7.0])
def test_moving_the_panel_changes_the_count_by_the_distance_over_the_stride(physics, d_far):
    w = walker()
    texture, distance = physics.texture_index(), physics.distance()
    try:
        physics.set_stimulus(texture, 3.0)
        near = w.walk(physics).strides
        physics.set_stimulus(texture, d_far)
        far = w.walk(physics).strides
    finally:
        physics.set_stimulus(texture, distance)
    assert abs((far - near) - (d_far - 3.0) / STRIDE_M) <= 1.0 / SUBSTEPS + 1e-9


def test_a_bigger_hand_touches_sooner(at_3m):
    w = walker()
    plain = w.walk(at_3m).strides
    radius = float(at_3m.model.geom_size[at_3m.model.name2id(HAND_GEOM, "geom")][0])
    with changed_model(at_3m, "geom_size", HAND_GEOM, [radius + 0.25, 0.0, 0.0]):
        bigger = w.walk(at_3m).strides
    assert abs((plain - bigger) - 0.25 / STRIDE_M) <= 1.0 / SUBSTEPS + 1e-9
    assert w.walk(at_3m).strides == plain  # the model is as it was


def test_moving_the_hand_forward_in_the_model_shortens_the_walk(at_3m):
    w = walker()
    plain = w.walk(at_3m).strides
    hand_pos = at_3m.model.geom_pos[at_3m.model.name2id(HAND_GEOM, "geom")].copy()
    with changed_model(at_3m, "geom_pos", HAND_GEOM, hand_pos + [0.5, 0.0, 0.0]):
        moved = w.walk(at_3m).strides
    assert abs((plain - moved) - 0.5 / STRIDE_M) <= 1.0 / SUBSTEPS + 1e-9


def test_moving_the_panel_geom_changes_the_walk_but_not_the_scene_distance(at_3m):
    """The scene's distance stays 3 m while the panel's geom moves 0.4 m away in the model: the
    walk follows the geometry, the attribute does not enter."""
    w = walker()
    plain = w.walk(at_3m).strides
    panel_pos = at_3m.model.geom_pos[at_3m.model.name2id(PANEL_GEOM, "geom")].copy()
    with changed_model(at_3m, "geom_pos", PANEL_GEOM, panel_pos + [0.4, 0.0, 0.0]):
        assert at_3m.distance() == 3.0
        moved = w.walk(at_3m).strides
    assert abs((moved - plain) - 0.4 / STRIDE_M) <= 1.0 / SUBSTEPS + 1e-9


def test_a_panel_out_of_reach_is_an_error_and_the_body_is_put_back(physics):
    w = walker(stride_m=1.0)  # few strides to the 100 m query range
    texture, distance = physics.texture_index(), physics.distance()
    lateral = physics.lateral_position()
    try:
        physics.set_lateral_position(0.1)
        physics.set_stimulus(texture, 150.0)
        before = _body_state(physics)
        with pytest.raises(RuntimeError, match="did not reach the panel"):
            w.walk(physics)
        after = _body_state(physics)
    finally:
        physics.set_stimulus(texture, distance)
        physics.set_lateral_position(lateral)
    for key, value in before.items():
        np.testing.assert_array_equal(after[key], value, err_msg=key)


# -- the body is put back -------------------------------------------------------------------------
@pytest.mark.parametrize("lateral_m", [0.05, 0.1])
def test_the_body_is_restored_exactly_after_a_walk(at_3m, lateral_m):
    at_3m.set_lateral_position(lateral_m)
    at_3m.set_pan_deg(7.5)
    before = _body_state(at_3m)
    w = walker(stride_slip=0.1, seed=3)
    result = w.walk(at_3m)
    w.reach_strides(at_3m)
    w.reach_strides(at_3m, 5.0)
    after = _body_state(at_3m)
    for key, value in before.items():
        np.testing.assert_array_equal(after[key], value, err_msg=key)
    assert at_3m.lateral_position() == lateral_m
    assert at_3m.forward_position() == 0.0
    assert at_3m.pan_deg() == pytest.approx(7.5)
    assert result.travelled_m > 2.9  # it did walk


def test_the_walk_starts_from_l0_whatever_the_lateral_position(at_3m):
    w = walker()
    counts = []
    for lateral_m in (0.0, 0.05, 0.1):
        at_3m.set_lateral_position(lateral_m)
        counts.append((w.walk(at_3m).strides, w.reach_strides(at_3m)))
    assert counts[0] == counts[1] == counts[2]


def test_forward_position_round_trips_and_refuses_non_finite(at_3m):
    at_3m.set_forward_position(0.25)
    try:
        assert at_3m.forward_position() == 0.25
        assert Walker.gap_m(at_3m) == pytest.approx(3.0 - 0.017 - 0.25, abs=1e-9)
        for bad in (float("nan"), float("inf"), "1"):
            with pytest.raises(ValueError, match="forward position"):
                at_3m.set_forward_position(bad)
    finally:
        at_3m.set_forward_position(0.0)
        at_3m.forward()
    assert at_3m.forward_position() == 0.0


# -- slip, substeps, growth ------------------------------------------------------------------------
@pytest.mark.parametrize("substeps", [1, 4, SUBSTEPS])
def test_a_slip_free_walk_is_the_reach_to_within_one_substep(at_3m, substeps):
    w = walker(substeps=substeps)
    reach = w.reach_strides(at_3m)
    walks = [w.walk(at_3m) for _ in range(3)]
    assert walks[0] == walks[1] == walks[2]
    strides = walks[0].strides
    assert reach - 1e-9 <= strides < reach + 1.0 / substeps + 1e-9
    # the count is whole strides plus whole substeps
    assert strides * substeps == pytest.approx(round(strides * substeps), abs=1e-9)
    assert walks[0].travelled_m == pytest.approx(strides * STRIDE_M, abs=1e-9)


def test_reach_strides_for_another_distance_is_the_gap_there(at_3m):
    w = walker()
    texture = at_3m.texture_index()
    predicted = w.reach_strides(at_3m, 6.5)
    at_3m.set_stimulus(texture, 6.5)
    assert w.reach_strides(at_3m) == pytest.approx(predicted, abs=1e-9)
    assert predicted == pytest.approx((6.5 - 0.017) / STRIDE_M, abs=1e-6)


def test_slip_is_reproducible_for_a_seed_and_varies_with_it(at_3m):
    def walks(seed):
        w = walker(stride_slip=0.05, seed=seed)
        return [w.walk(at_3m).strides for _ in range(4)]

    reach = walker().reach_strides(at_3m)
    first, again, other = walks(11), walks(11), walks(12)
    assert first == again
    assert first != other
    assert len(set(first)) > 1  # each walk draws new slips
    # slip around the true stride: each count stays near the slip-free reach (sd ≈ 0.4 strides)
    assert all(abs(n - reach) < 5.0 for n in first + other)


def test_growth_shortens_the_count_by_the_growth_factor(at_3m):
    w = walker(growth_factor=1.1)
    assert w.true_stride_m == STRIDE_M
    young_reach, young = w.reach_strides(at_3m), w.walk(at_3m).strides
    w.grown = True
    assert w.true_stride_m == pytest.approx(STRIDE_M * 1.1)
    grown_reach, grown = w.reach_strides(at_3m), w.walk(at_3m).strides
    assert grown_reach == pytest.approx(young_reach / 1.1, rel=1e-12)
    assert abs(grown - young / 1.1) <= 1.0 / SUBSTEPS + 1e-9
    assert grown < young - 5  # not a rounding difference: about 5.4 strides fewer
    w.grown = False
    assert w.walk(at_3m).strides == young


def test_the_walker_state_round_trips_the_slip_stream_and_growth(at_3m):
    a = walker(stride_slip=0.05, seed=5, growth_factor=1.2)
    a.walk(at_3m)
    a.grown = True
    state = a.state_dict()
    expected = [a.walk(at_3m).strides for _ in range(2)]
    b = walker(stride_slip=0.05, seed=99, growth_factor=1.2)
    b.load_state_dict(state)
    assert b.grown is True
    assert [b.walk(at_3m).strides for _ in range(2)] == expected


# -- deciding to walk -----------------------------------------------------------------------------
def test_decide_walks_at_the_given_frequency():
    w = walker(seed=4)
    decisions = [w.decide(0.3) for _ in range(4000)]
    assert abs(np.mean(decisions) - 0.3) < 0.03
    assert all(w.decide(1.0) for _ in range(200))
    assert not any(w.decide(0.0) for _ in range(200))


def test_deciding_draws_once_whatever_the_fraction(at_3m):
    """The slip draws after a decision do not depend on the fraction the decision was made at."""
    always, sometimes = walker(stride_slip=0.05, seed=8), walker(stride_slip=0.05, seed=8)
    assert always.decide(1.0)
    sometimes.decide(0.2)
    assert always.walk(at_3m) == sometimes.walk(at_3m)


def test_walk_robots_counts_only_the_robots_that_walked(at_3m):
    walkers = [walker(seed=seed) for seed in range(6)]
    counted, reach = walk_robots([at_3m] * 6, walkers, 0.5)
    assert len(counted) == len(reach) == 6
    assert any(n is None for n in counted) and any(n is not None for n in counted)
    single = walker().reach_strides(at_3m)
    assert reach == pytest.approx([single] * 6)
    for n in counted:
        assert n is None or single - 1e-9 <= n < single + 1.0 / SUBSTEPS + 1e-9
    none, reach_none = walk_robots([at_3m], [walker()], 0.0)
    assert none == [None] and reach_none == pytest.approx([single])


def test_walk_robots_needs_one_walker_per_robot(at_3m):
    with pytest.raises(ValueError):
        walk_robots([at_3m, at_3m], [walker()], 1.0)
