"""python -m parallax.tools.analysis.input_scaling: each input scaling of the distance network,
with and without the weighting, replayed on the same eye movements and compared in pairs."""

from __future__ import annotations

import json

import pytest

from parallax.tools.analysis import input_scaling as study_module


@pytest.fixture(scope="module")
def perturbed_run(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(
        tmp_path_factory.mktemp("run"),
        [
            "train.presentations=8",
            "curriculum.lateral_positions=[0.05,0.1,0.15,0.2]",
            "perturbation=rotate_blur",
            "perturbation.start_fraction=0.5",
        ],
    )


def test_per_input_scaling_undoes_the_weighting_and_no_scaling_does_not(perturbed_run, tmp_path):
    cache = tmp_path / "cache"
    result = study_module.study(
        [perturbed_run], ["per_input", "none"], [4.0], ["distance.y=1"], cache=cache
    )
    rows = {(r["input_scaling"], r["weighting"]): r for r in result["settings"]}
    assert set(rows) == {(s, w) for s in ("per_input", "none") for w in ("unweighted", "y=4")}
    effects = {e["input_scaling"]: e for e in result["weighting_effect"]}
    assert effects["per_input"]["queue_after"]["mean"] == pytest.approx(0.0, abs=1e-6)
    assert abs(effects["none"]["queue_after"]["mean"]) > 1e-6
    assert effects["none"]["queue_after"]["seeds"] == 1  # one run: no interval
    assert len(list(cache.iterdir())) == 4
    # resumed from the cache: no replay at all
    original = study_module.replay_errors
    study_module.replay_errors = None
    try:
        again = study_module.study(
            [perturbed_run], ["per_input", "none"], [4.0], ["distance.y=1"], cache=cache
        )
    finally:
        study_module.replay_errors = original
    assert json.dumps(again["settings"]) == json.dumps(result["settings"])
    text = study_module.format_markdown(result)
    assert "| none | y=4 |" in text and "| per_input | unweighted |" in text


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        study_module.main([str(tmp_path), "--json", str(tmp_path / "out.json")])
    assert stop.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not (tmp_path / "out.json").exists()
