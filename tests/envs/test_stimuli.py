"""Stimulus textures: photographs shipped with scikit-image, a user's folder, procedural
ablations."""

from __future__ import annotations

import itertools
import warnings

import cv2
import numpy as np
import pytest

from parallax.envs import stimuli
from parallax.envs.settings import PROCEDURAL_KINDS


def _photo_of(name: str) -> str:
    return name.split("[")[0]


def _thumbnails(textures: np.ndarray) -> np.ndarray:
    small = np.stack(
        [
            cv2.resize(
                cv2.cvtColor(np.ascontiguousarray(t), cv2.COLOR_RGB2GRAY),
                (24, 24),
                interpolation=cv2.INTER_AREA,
            )
            for t in textures
        ]
    ).reshape(len(textures), -1)
    small = small - small.mean(axis=1, keepdims=True)
    return small / np.linalg.norm(small, axis=1, keepdims=True)


def test_at_least_100_distinct_training_crops_from_real_photographs():
    train = stimuli.load_stimuli({"split": "train"})
    assert train.count >= 100 and train.textures.shape[1:] == (256, 256, 3)
    assert {_photo_of(n) for n in train.names} == set(stimuli.TRAIN_PHOTOS)
    assert len(set(train.names)) == train.count
    similarity = _thumbnails(train.textures) @ _thumbnails(train.textures).T
    np.fill_diagonal(similarity, 0)
    assert similarity.max() < 0.98, "two training textures are (nearly) the same"
    # Each crop really is a piece of its photograph (not noise): compare with the source pixels.
    name = train.names[0]
    photo = stimuli.photo(_photo_of(name))
    y, x, side = (int(part.split("=")[1]) for part in name[name.index("[") + 1 : -1].split(","))
    source = cv2.resize(photo[y : y + side, x : x + side], (256, 256), interpolation=cv2.INTER_AREA)
    assert np.abs(source.astype(int) - train.textures[0].astype(int)).mean() < 3


def test_held_out_crops_come_from_other_photographs():
    train = stimuli.load_stimuli({"split": "train"})
    heldout = stimuli.load_stimuli({"split": "heldout"})
    assert heldout.count >= 20
    train_photos = {_photo_of(n) for n in train.names}
    heldout_photos = {_photo_of(n) for n in heldout.names}
    assert not train_photos & heldout_photos
    assert stimuli.BACKGROUND_PHOTO not in train_photos | heldout_photos


def test_sets_are_decoded_once_and_read_only():
    first = stimuli.load_stimuli({"count": 5})
    assert stimuli.load_stimuli({"count": 5, "split": "train"}) is first
    with pytest.raises(ValueError):
        first.textures[0, 0, 0, 0] = 1


def test_a_small_set_spans_several_photographs():
    small = stimuli.load_stimuli({"count": 6})
    assert len({_photo_of(n) for n in small.names}) == 6


def test_user_folder_skips_unreadable_files_with_a_warning_naming_them(tmp_path):
    rng = np.random.default_rng(0)
    for k in range(3):
        cv2.imwrite(
            str(tmp_path / f"img{k}.png"), rng.integers(0, 256, (40 + k, 60, 3), dtype=np.uint8)
        )
    (tmp_path / "broken.jpg").write_bytes(b"not a jpeg at all")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.warns(UserWarning, match="broken.jpg.*notes.txt"):
        folder = stimuli.load_stimuli({"source": "dir", "dir": str(tmp_path), "resolution": 32})
    assert folder.count == 3 and folder.names == ("img0.png", "img1.png", "img2.png")
    assert folder.textures.shape == (3, 32, 32, 3)
    # `stimuli.dir=<folder>` on top of the shipped config (source: skimage) means the folder
    # (already decoded: the cached set comes back).
    assert (
        stimuli.load_stimuli({"source": "skimage", "dir": str(tmp_path), "resolution": 32})
        is folder
    )


def test_user_folder_with_too_few_images_is_a_clear_error(tmp_path):
    (tmp_path / "a.png").write_bytes(b"garbage")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning besides the error: one message, not two
        with pytest.raises(stimuli.StimulusError, match="no readable image") as error:
            stimuli.load_stimuli({"source": "dir", "dir": str(tmp_path)})
    assert (error.value.key, error.value.value) == ("dir", str(tmp_path))
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((8, 8, 3), np.uint8))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match="stimuli.count=5"):
            stimuli.load_stimuli({"source": "dir", "dir": str(tmp_path), "count": 5})
    with pytest.raises(ValueError, match="not a folder"):
        stimuli.load_stimuli({"source": "dir", "dir": str(tmp_path / "missing")})


@pytest.mark.parametrize("kind", PROCEDURAL_KINDS)
def test_procedural_textures_are_deterministic_and_split(kind):
    settings = {"source": "procedural", "kind": kind, "count": 4, "resolution": 64}
    train = stimuli.load_stimuli(settings)
    heldout = stimuli.load_stimuli({**settings, "split": "heldout"})
    rebuilt = stimuli._build(stimuli.normalise_settings(settings))
    assert np.array_equal(train.textures, rebuilt.textures)
    for a, b in itertools.product(train.textures, heldout.textures):
        assert not np.array_equal(a, b)
    assert all(t.std() > 20 for t in train.textures)


@pytest.mark.parametrize(
    "settings,named",
    [
        # what only the set can tell; the settings' ranges and choices are parallax.config's
        # (tests/config/test_bad_input.py: env.stimuli.*)
        ({"colour": "red"}, "colour"),
        ({"source": "dir"}, "stimuli.dir"),
        ({"count": 400}, "400"),
    ],
)
def test_bad_settings_are_named(settings, named):
    with pytest.raises(ValueError) as error:
        stimuli.load_stimuli(settings)
    assert named in str(error.value)
