"""parallax-eval on textures of another kind than the training photographs, and on those."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from parallax.tools.evaluate import evaluate, main


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(tmp_path_factory.mktemp("run"), ["train.presentations=4"])


def test_held_out_textures_of_another_kind(tiny_run, tmp_path):
    common = {"distances": [4.0, 6.0], "between": [], "start_jitter": "off"}
    photos = evaluate(tiny_run, out=tmp_path / "photos", **common)
    assert photos["stimuli"]["source"] == "skimage" and photos["stimuli"]["split"] == "heldout"
    noise = evaluate(
        tiny_run,
        out=tmp_path / "noise",
        stimuli=["env.stimuli.source=procedural", "env.stimuli.kind=pink_noise"],
        sampled=False,
        **common,
    )
    assert list(noise["mae"]) == ["greedy"] and list(photos["mae"]) == ["greedy", "sampled"]
    assert noise["stimuli"]["source"] == "procedural" and noise["stimuli"]["kind"] == "pink_noise"
    assert noise["greedy_samples"]["grid"]["pans"] != photos["greedy_samples"]["grid"]["pans"]
    folder = tmp_path / "images"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(2):
        cv2.imwrite(str(folder / f"{k}.png"), rng.integers(0, 255, (40, 60, 3), dtype=np.uint8))
    # the run's count of textures is more than the folder holds: every image of it instead
    mine_settings = [f"env.stimuli.dir={folder}", "env.stimuli.count=null"]
    mine = evaluate(tiny_run, out=tmp_path / "mine", stimuli=mine_settings, **common)
    assert mine["stimuli"]["dir"] == str(folder)
    assert len(mine["greedy_samples"]["grid"]["pans"]) == 2


def test_the_training_photographs_on_request(tiny_run, tmp_path):
    common = {"distances": [4.0, 6.0], "between": [], "start_jitter": "off", "sampled": False}
    held_out = evaluate(tiny_run, out=tmp_path / "held_out", **common)
    seen = evaluate(tiny_run, out=tmp_path / "seen", split="train", **common)
    assert held_out["stimuli"]["split"] == "heldout" and seen["stimuli"]["split"] == "train"
    # other photographs: other images, so other pans
    assert seen["greedy_samples"]["grid"]["pans"] != held_out["greedy_samples"]["grid"]["pans"]
    with pytest.raises(ValueError, match="--split"):
        evaluate(tiny_run, out=tmp_path / "none", split="test", **common)
    assert not (tmp_path / "none").exists()


@pytest.mark.parametrize(
    "item, named",
    [
        ("env.stimuli.split=train", "--split"),
        ("env.stimuli.colour=red", "env.stimuli.colour"),
        ("policy.actor_lr=1", "policy.actor_lr=1"),
        ("env.stimuli.kind=plaid", "env.stimuli.kind=plaid"),
    ],
)
def test_a_bad_stimulus_setting_is_one_line_and_exit_2(tiny_run, tmp_path, capsys, item, named):
    with pytest.raises(SystemExit) as exit_info:
        main([str(tiny_run), item, "--out", str(tmp_path / "out"), "--distances", "4.0"])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert named in line
    assert not (tmp_path / "out").exists()


def test_between_none_skips_them_and_the_command_says_what_and_where(tiny_run, tmp_path, capsys):
    out = tmp_path / "out"
    common = ["--distances", "4.0", "6.0", "--greedy-only", "--start-jitter", "off"]
    main([str(tiny_run), "--between", "none", "--out", str(out), *common])
    result = json.loads((out / "eval.json").read_text())
    assert "between" not in result["greedy_samples"]
    assert "distance_between_grid" not in result
    # stored absolute, so that the analyses find the run from any working directory
    assert result["run_dir"] == str(tiny_run.resolve())
    err = capsys.readouterr().err
    assert f"[parallax-eval] frozen trials of {(tiny_run / 'checkpoint.pt').resolve()}" in err
    assert "[parallax-eval]   perturbed: no" in err
    assert "[parallax-eval]   trials: 2 (2 distances, greedy; 1 robot at a time)" in err
    assert "[parallax-eval] wrote eval.json, eval_mae_per_position.png" in err
    assert f"to {out.resolve()}" in err
    with pytest.raises(SystemExit) as exit_info:
        main([str(tiny_run), "--between", "none", "5.5", "--out", str(tmp_path / "no")])
    assert exit_info.value.code == 2 and not (tmp_path / "no").exists()
    assert "none stands alone" in capsys.readouterr().err
