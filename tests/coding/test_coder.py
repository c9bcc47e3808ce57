"""MultiScaleCoder, the interface the trainer uses (paper §3.3–3.4, eqs. 3–6), and its configs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate

import parallax.config  # noqa: F401 — registers the schema that the conf/coder files extend
from parallax.coding import CoderOutput, MultiScaleCoder, save_png
from parallax.coding.retina import as_gray_batch

CONF = Path(__file__).resolve().parents[2] / "conf"
SPECS = {
    "coarse": {"window": 250, "subsample": 8, "patch": 10, "stride": 1},
    "fine": {"window": 150, "subsample": 2, "patch": 10, "stride": 4},
}
SMALL_SPECS = {
    "coarse": {"window": 64, "subsample": 4, "patch": 10, "stride": 2},
    "fine": {"window": 40, "subsample": 2, "patch": 10, "stride": 5},
}


def _coder(**overrides) -> MultiScaleCoder:
    arguments = dict(
        scales=["coarse", "fine"],
        scale_specs=SPECS,
        atoms=288,
        sparsity=10,
        learning_rate=0.2,
        normalisation="per_half",
        learn=True,
        seed=0,
        image_size=256,
    )
    arguments.update(overrides)
    return MultiScaleCoder(**arguments)


def _photo_batch(batch: int, size: int = 256, shift: int = 0) -> np.ndarray:
    """Crops of a photograph, the content moved right by ``shift`` px."""
    import skimage.data

    photo = skimage.data.astronaut()
    crops = [
        np.roll(photo[40 * index : 40 * index + size, 100 : 100 + size], shift, axis=1)
        for index in range(batch)
    ]
    return np.stack(crops)


def test_outputs_have_the_promised_shapes_and_meaning() -> None:
    coder = _coder(learn=False)
    assert coder.state_dim == 576
    coder.set_reference(_photo_batch(2))
    output = coder(_photo_batch(2, shift=3))
    assert isinstance(output, CoderOutput)
    assert output.state.shape == (2, 576) and output.state.dtype == torch.float32
    assert output.reward.shape == (2,) and output.reward.dtype == torch.float32
    assert set(output.errors) == {"coarse", "fine"}
    torch.testing.assert_close(output.reward, -(output.errors["coarse"] + output.errors["fine"]))
    assert ((output.errors["coarse"] > 0) & (output.errors["coarse"] < 1)).all()
    assert (output.state >= 0).all() and torch.isfinite(output.state).all()


def test_state_is_pooled_squared_coefficients_per_scale_in_order() -> None:
    coder = _coder(learn=False)
    images = _photo_batch(1)
    coder.set_reference(images)
    gray = as_gray_batch(images)
    fine = coder.coders["fine"]
    pairs = fine.patch_pairs(gray)[0]
    code = fine.encode(pairs)
    expected_theta = code.codes.square().mean(dim=0)
    torch.testing.assert_close(coder(images).state[0, 288:], expected_theta)
    # Σ_n θ_n = mean over patches of Σ_n b_n²; with k=10 that stays below ‖γ‖² = 2.
    assert 0 < expected_theta.sum() < 2


def test_learning_updates_after_encoding_and_keeps_atoms_unit_norm() -> None:
    coder = _coder()
    frozen = _coder(learn=False)
    images = _photo_batch(1)
    for model in (coder, frozen):
        model.set_reference(images)
    before = {name: tensor.clone() for name, tensor in coder.dictionaries.items()}
    learning_output = coder(images)
    frozen_output = frozen(images)
    torch.testing.assert_close(
        learning_output.state, frozen_output.state
    )  # outputs precede the step
    for name, dictionary in coder.dictionaries.items():
        assert not torch.equal(dictionary, before[name])
        torch.testing.assert_close(dictionary.norm(dim=1), torch.ones(288))
        assert torch.equal(frozen.dictionaries[name], before[name])
    # learn=False on the call overrides the module flag
    snapshot = coder.dictionaries["coarse"].clone()
    coder(images, learn=False)
    assert torch.equal(coder.dictionaries["coarse"], snapshot)


def test_a_mean_batch_update_averages_over_all_patches_of_all_images() -> None:
    single, double = _coder(), _coder(robot_updates="mean")
    image = _photo_batch(1)
    single.set_reference(image)
    double.set_reference(np.concatenate([image, image]))
    single(image)
    double(np.concatenate([image, image]))
    for name in ("coarse", "fine"):
        torch.testing.assert_close(
            single.dictionaries[name], double.dictionaries[name], atol=1e-6, rtol=0
        )


def test_a_summed_batch_update_is_each_images_step_added_up() -> None:
    # two images that are the same: the sum is one image's step at twice η
    summed, twice = _coder(), _coder(learning_rate=0.4)
    image = _photo_batch(1)
    summed.set_reference(np.concatenate([image, image]))
    twice.set_reference(image)
    summed(np.concatenate([image, image]))
    twice(image)
    for name in ("coarse", "fine"):
        torch.testing.assert_close(
            summed.dictionaries[name], twice.dictionaries[name], atol=1e-6, rtol=0
        )


def test_training_lowers_the_error_on_a_repeated_view() -> None:
    coder = _coder(scales=["fine"])
    coder.set_reference(_photo_batch(1))
    view = _photo_batch(1, shift=2)
    first = coder(view).errors["fine"].item()
    for _ in range(30):
        coder(view)
    assert coder(view).errors["fine"].item() < 0.8 * first


def test_same_seed_same_numbers_and_scales_seeded_independently() -> None:
    first, second = _coder(seed=5), _coder(seed=5)
    images = _photo_batch(1)
    outputs = []
    for coder in (first, second):
        coder.set_reference(images)
        coder(images)
        outputs.append(coder(_photo_batch(1, shift=1)))
    assert torch.equal(outputs[0].state, outputs[1].state)
    assert torch.equal(outputs[0].reward, outputs[1].reward)
    assert not torch.equal(
        _coder(seed=6).dictionaries["coarse"], _coder(seed=5).dictionaries["coarse"]
    )
    coarse_only = _coder(seed=5, scales=["coarse"])
    assert torch.equal(coarse_only.dictionaries["coarse"], _coder(seed=5).dictionaries["coarse"])
    assert not torch.equal(
        _coder(seed=5).dictionaries["coarse"], _coder(seed=5).dictionaries["fine"]
    )


def test_state_dict_round_trip_carries_dictionaries_but_not_the_reference() -> None:
    trained = _coder(seed=1)
    trained.set_reference(_photo_batch(1))
    trained(_photo_batch(1, shift=2))
    state = trained.state_dict()
    assert set(state) == {"coders.coarse.dictionary", "coders.fine.dictionary"}
    restored = _coder(seed=2)
    restored.load_state_dict(state)
    restored.set_reference(_photo_batch(1))
    for model in (trained, restored):
        model.learn = False
    torch.testing.assert_close(
        restored(_photo_batch(1, shift=4)).state, trained(_photo_batch(1, shift=4)).state
    )


def test_frozen_coder_notices_a_loaded_dictionary() -> None:
    coder = _coder(learn=False, scales=["fine"])
    coder.set_reference(_photo_batch(1))
    before = coder(_photo_batch(1, shift=1)).state
    other = _coder(seed=9, scales=["fine"])
    coder.load_state_dict(other.state_dict())
    other.set_reference(_photo_batch(1))
    after = coder(_photo_batch(1, shift=1)).state
    assert not torch.equal(before, after)
    torch.testing.assert_close(after, other(_photo_batch(1, shift=1), learn=False).state)


def test_flat_images_give_finite_outputs() -> None:
    coder = _coder()
    flat = np.full((2, 256, 256, 3), 90, dtype=np.uint8)
    coder.set_reference(flat)
    output = coder(flat)
    assert torch.isfinite(output.state).all() and torch.equal(output.reward, torch.zeros(2))
    assert all(torch.isfinite(dictionary).all() for dictionary in coder.dictionaries.values())


def test_gray_float_and_tensor_inputs_agree_with_uint8_rgb() -> None:
    coder = _coder(learn=False, image_size=(128, 160), scale_specs=SMALL_SPECS)
    rgb = _photo_batch(1, size=160)[:, :128]
    coder.set_reference(rgb)
    from_rgb = coder(rgb).state
    gray = as_gray_batch(rgb).numpy()
    coder.set_reference(torch.from_numpy(gray))
    torch.testing.assert_close(coder(gray).state, from_rgb, atol=1e-5, rtol=1e-4)


def test_joint_normalisation_runs_and_differs_from_per_half() -> None:
    images = _photo_batch(1)
    per_half, joint = _coder(learn=False), _coder(learn=False, normalisation="joint")
    for coder in (per_half, joint):
        coder.set_reference(images)
    assert not torch.allclose(
        per_half(_photo_batch(1, shift=5)).state, joint(_photo_batch(1, shift=5)).state
    )


def test_recompute_pursuit_gives_the_same_outputs() -> None:
    images = _photo_batch(1)
    fast, straightforward = _coder(learn=False), _coder(learn=False, pursuit="recompute")
    for coder in (fast, straightforward):
        coder.set_reference(images)
    torch.testing.assert_close(
        fast(_photo_batch(1, shift=2)).reward,
        straightforward(_photo_batch(1, shift=2)).reward,
        atol=1e-4,
        rtol=0,
    )


def test_compiled_and_torch_pursuit_loops_learn_bit_identical_dictionaries() -> None:
    from parallax.coding import native

    if native.load_kernels() is None:
        pytest.skip(f"the fused pursuit kernel is unavailable: {native.kernel_failure()}")
    coders = [
        _coder(scales=["coarse", "fine"], pursuit=pursuit) for pursuit in ("gram_cpp", "gram_torch")
    ]
    for coder in coders:
        coder.set_reference(_photo_batch(2))
    for shift in (1, 3, 5):
        compiled, loop = (coder(_photo_batch(2, shift=shift)) for coder in coders)
        assert torch.equal(compiled.state, loop.state) and torch.equal(compiled.reward, loop.reward)
    for name in ("coarse", "fine"):
        assert torch.equal(coders[0].dictionaries[name], coders[1].dictionaries[name])


@pytest.mark.parametrize("normalisation", ["per_half", "joint"])
def test_the_one_call_encoding_is_the_separate_calls_bit_for_bit(normalisation: str) -> None:
    from parallax.coding import native
    from parallax.coding.dictionary import pooled_activity_of, reconstruction_error

    if native.load_kernels() is None:
        pytest.skip(f"the fused pursuit kernel is unavailable: {native.kernel_failure()}")
    coder = _coder(pursuit="gram_cpp", normalisation=normalisation)
    coder.set_reference(_photo_batch(3))
    current = _photo_batch(3, shift=2)
    current[1] = 128  # a flat image: every patch of it near-constant
    gray = as_gray_batch(current)
    for scale in coder.coders.values():
        output, code = scale.encode_images(gray)
        assert code.codes is None  # the one call ran
        pairs = scale.patch_pairs(gray)
        batch, patches, dim = pairs.shape
        separate = scale.encode(pairs.reshape(batch * patches, dim), dense_codes=False)
        assert torch.equal(code.atom_indices, separate.atom_indices)
        assert torch.equal(code.coefficients, separate.coefficients)
        assert torch.equal(code.residuals, separate.residuals)
        assert torch.equal(output.activity, pooled_activity_of(separate, batch, scale.atoms))
        residuals = separate.residuals.reshape(batch, patches, dim)
        assert torch.equal(output.error, reconstruction_error(pairs, residuals))
        assert torch.isfinite(output.error).all()


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        # the settings' ranges are parallax.config's (tests/config/test_bad_input.py); the
        # coder checks what only its caller knows: the images' size and the pursuit to use
        ({"image_size": 200}, r"scale_specs\.coarse\.window=250"),
        ({"image_size": (256, 200)}, r"scale_specs\.coarse\.window=250"),
        ({"pursuit": "omp"}, "pursuit"),
    ],
)
def test_bad_arguments_are_refused_with_the_key_named(overrides: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        _coder(**overrides)


def test_the_defaults_are_the_papers_coder() -> None:
    coder = MultiScaleCoder(seed=0, image_size=256)
    assert coder.scales == ["coarse", "fine"] and coder.state_dim == 2 * 288
    assert coder.coders["coarse"].spec.patch_count == 529
    assert coder.coders["fine"].spec.patch_count == 289


def test_misuse_at_call_time_is_explained() -> None:
    coder = _coder(scales=["fine"])
    with pytest.raises(RuntimeError, match="set_reference"):
        coder(_photo_batch(1))
    coder.set_reference(_photo_batch(2))
    with pytest.raises(ValueError, match="1 images for 2 references"):
        coder(_photo_batch(1))
    with pytest.raises(ValueError, match="window 150"):
        coder(np.zeros((2, 100, 100), dtype=np.float32))


def test_atom_grid_draws_every_pair(tmp_path: Path) -> None:
    coder = _coder(atoms=12, scales=["fine"])
    grid = coder.atom_grid("fine", columns=4, zoom=2, gap=1)
    assert grid.dtype == np.uint8 and grid.ndim == 2
    assert grid.shape == (2 * (3 * 11 + 1), 2 * (4 * 22 + 1))
    dictionary = coder.dictionaries["fine"][0].numpy()
    first_half = grid[2 : 2 + 20 : 2, 2 : 2 + 20 : 2].astype(float) - 128
    peak = np.abs(dictionary).max()
    np.testing.assert_allclose(
        first_half, np.rint(127 * dictionary[:100].reshape(10, 10) / peak), atol=1
    )
    path = save_png(grid, tmp_path / "atoms.png")
    assert path.stat().st_size > 0
    with pytest.raises(ValueError, match="unknown scale"):
        coder.atom_grid("coarse")


@pytest.mark.parametrize(
    ("name", "scales"),
    [("two_scale", ["coarse", "fine"]), ("coarse", ["coarse"]), ("fine", ["fine"])],
)
def test_configs_instantiate(name: str, scales: list[str]) -> None:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        config = compose(overrides=[f"+coder={name}"])
    coder = instantiate(config.coder, image_size=256, seed=0)
    assert isinstance(coder, MultiScaleCoder) and coder.scales == scales
    assert coder.state_dim == 288 * len(scales)


def test_scale_ablation_is_one_override() -> None:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        config = compose(
            overrides=["+coder=two_scale", "coder.scales=[coarse]", "coder.learn=false"]
        )
    coder = instantiate(config.coder, image_size=256, seed=0)
    assert coder.scales == ["coarse"] and coder.learn is False


@pytest.mark.parametrize("pursuit", ["gram", "recompute"])
def test_the_consecutive_pairing_codes_each_image_against_the_one_before(pursuit: str) -> None:
    frames = [_photo_batch(2, shift=s) for s in (0, 3, 6)]
    consecutive = _coder(pairing="consecutive", pursuit=pursuit)
    consecutive.set_reference(frames[0])  # I(−1) is I0
    against_previous = _coder(pursuit=pursuit)
    for before, now in zip(frames, frames[1:]):
        against_previous.set_reference(before)
        expected = against_previous.encode_frame(now).output
        got = consecutive.encode_frame(now).output
        torch.testing.assert_close(got.state, expected.state, rtol=0, atol=0)
        torch.testing.assert_close(got.reward, expected.reward, rtol=0, atol=0)
    # one robot at a time moves only its own reference on
    consecutive.set_reference(frames[0])
    consecutive.encode_frame(frames[1][1:], robots=slice(1, 2))
    first = consecutive.encode(frames[0][:1], robots=slice(0, 1)).output.reward
    against_previous.set_reference(frames[0])
    same = against_previous.encode(frames[0][:1], robots=slice(0, 1)).output.reward
    torch.testing.assert_close(first, same, rtol=0, atol=0)


@pytest.mark.parametrize("normalisation", ["per_half", "joint"])
@pytest.mark.parametrize("pairing", ["reference", "consecutive"])
def test_one_compiled_call_encodes_and_learns_as_the_scales_do_one_by_one(
    normalisation: str, pairing: str
) -> None:
    """Every scale in one compiled call (the first on this thread, the others and the dictionary
    steps on the kernels' helper thread) gives each scale's own calls' numbers, bit for bit:
    outputs, codes, dictionaries, Gram matrices and the consecutive pairing's references, over
    chunks of robots and several steps."""
    from parallax.coding import DictionarySteps, native

    if native.load_kernels() is None:
        pytest.skip("the compiled kernels are unavailable here")
    one_call, by_scale = (
        _coder(normalisation=normalisation, pairing=pairing, scale_specs=SMALL_SPECS, image_size=64)
        for _ in range(2)
    )
    by_scale._compiled_scales = lambda: None  # each scale's own calls, on the Python helper
    assert one_call._compiled_scales() is not None
    references = _photo_batch(3, size=64)
    one_call.set_reference(references)
    by_scale.set_reference(references)
    for shift in range(1, 4):
        images = _photo_batch(3, size=64, shift=shift)
        chunks = (slice(0, 2), slice(2, 3))
        mine = [one_call.encode_frame(images[robots], robots) for robots in chunks]
        theirs = [by_scale.encode_frame(images[robots], robots) for robots in chunks]
        for got, expected in zip(mine, theirs, strict=True):
            assert torch.equal(got.output.state, expected.output.state)
            assert torch.equal(got.output.reward, expected.output.reward)
            for scale in ("coarse", "fine"):
                assert torch.equal(got.output.errors[scale], expected.output.errors[scale])
                for part in ("atom_indices", "coefficients", "residuals"):
                    assert torch.equal(
                        getattr(got.codes[scale], part), getattr(expected.codes[scale], part)
                    )
        steps = one_call.learn_from_async(mine)
        assert isinstance(steps, DictionarySteps)
        steps.result()
        by_scale.learn_from_async(theirs).result()
        for scale in ("coarse", "fine"):
            mine_scale, their_scale = one_call.coders[scale], by_scale.coders[scale]
            assert torch.equal(mine_scale.dictionary, their_scale.dictionary)
            assert torch.equal(mine_scale.gram(), their_scale.gram())
            assert torch.equal(mine_scale.reference, their_scale.reference)


def test_a_failed_compiled_dictionary_step_raises_when_waited_for() -> None:
    """An error on the kernels' helper thread reaches the caller of ``result()``."""
    from parallax.coding import native

    compiled = native.load_kernels()
    if compiled is None:
        pytest.skip("the compiled kernels are unavailable here")
    dictionary = torch.zeros(4, 6)
    picks = torch.full((2, 1), 9)  # atom 9 of 4
    pending = compiled.start_dictionary_steps(
        [dictionary], [[picks]], [[torch.ones(2, 1)]], [[torch.ones(2, 6)]], [0.1], 1e-12
    )
    with pytest.raises(RuntimeError, match="not one of the 4 atoms"):
        pending.wait()
