"""Which experiment files are trained and which are replays (parallax.tools.experiments)."""

from __future__ import annotations

import pytest

from parallax.tools.experiments import main, plan, settings


def test_distance_only_variants_are_replays_of_the_trained_file():
    names = [
        "recipe_multi_5_20_weighted",
        "recipe_multi_5_20",
        "without_lm_weight_decay",
        "without_best_readout",
        "without_reward_change",
        "paper_multi_5_20",
        "paper_multi_5_20_weighted",
    ]
    lines = [p.line() for p in plan(names)]
    assert lines == [
        "train recipe_multi_5_20_weighted",
        "replay recipe_multi_5_20 recipe_multi_5_20_weighted distance.weighting=false",
        "replay without_lm_weight_decay recipe_multi_5_20_weighted distance.lm.weight_decay=0.0",
        "replay without_best_readout recipe_multi_5_20_weighted train.distance_readout=last",
        # the eye's own settings differ: it must be trained
        "train without_reward_change",
        "train paper_multi_5_20",
        "replay paper_multi_5_20_weighted paper_multi_5_20 distance.weighting=true",
    ]


def test_a_replays_overrides_give_the_replayed_files_config():
    plans = plan(["paper_multi_5_10", "recipe_multi_5_20_weighted", "without_best_readout"])
    assert [p.source for p in plans] == [None, None, "recipe_multi_5_20_weighted"]
    for p in plans:
        if p.source is not None:
            rebuilt = settings(p.source, list(p.overrides))
            assert rebuilt == settings(p.name)


def test_an_unknown_experiment_is_one_line_and_exit_2(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["recipe_single_5", "no_such_file"])
    assert exit_info.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    (line,) = captured.err.strip().splitlines()
    assert "experiment=no_such_file" in line
