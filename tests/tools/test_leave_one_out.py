"""The leave-one-out table: runs matched to experiment files, differences paired by seed."""

from __future__ import annotations

import json

import pytest
import yaml
from omegaconf import OmegaConf

from parallax.config import compose
from parallax.tools.report.leave_one_out import RECIPE, leave_one_out, main, markdown, variants


def _fake_run(folder, name, seed, eye, distance_after):
    """A finished run of ``experiment=name``: its composed config, a summary with the last
    trials before and after the perturbation, and a held-out eval after it."""
    cfg = OmegaConf.to_container(compose([f"experiment={name}", f"seed={seed}"]), resolve=True)
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(yaml.safe_dump(cfg))
    positions = [str(int(round(100 * l))) for l in cfg["curriculum"]["lateral_positions"]]
    trials = {p: {"mean": eye, "var": 0.0, "trials": 100} for p in positions}
    start = round(cfg["perturbation"]["start_fraction"] * cfg["train"]["presentations"])
    summary = {
        "presentations": cfg["train"]["presentations"],
        "last_trials": trials,
        "before_perturbation": {"presentations": start, "last_trials": trials},
    }
    (folder / "summary.json").write_text(json.dumps(summary))
    by_range = {"3-4.9": distance_after, "5-6.9": distance_after, "7-10": distance_after}
    by_range["total"] = distance_after
    result = {
        "presentations": cfg["train"]["presentations"],
        "perturbed": True,
        "distance": {"by_range": by_range, "trials": 71},
    }
    (folder / "eval.json").write_text(json.dumps(result))


def test_each_row_is_paired_with_the_recipe_on_its_seeds(tmp_path):
    for seed, (eye, dist) in enumerate([(0.10, 1.0), (0.12, 1.4), (0.11, 1.2)]):
        _fake_run(tmp_path / "recipe" / f"s{seed}", RECIPE, seed, eye, dist)
    # removing the improvement makes the distance worse on two seeds of the two it has
    _fake_run(tmp_path / "loo" / "a", "without_reward_change", 0, 0.10, 1.5)
    _fake_run(tmp_path / "loo" / "b", "without_reward_change", 1, 0.11, 1.6)
    result = leave_one_out([tmp_path / "recipe", tmp_path / "loo"])
    rows = {r["experiment"]: r for r in result["rows"]}
    assert set(rows) == {RECIPE, *variants()}
    assert rows[RECIPE]["seeds"] == [0, 1, 2]
    change = rows["without_reward_change"]
    assert change["seeds"] == [0, 1] and change["section"].startswith("§6 ")
    assert change["distance_after"]["mean"] == pytest.approx(1.55)
    assert change["distance_after_change"]["mean"] == pytest.approx(0.35)
    assert change["distance_after_worse"] == [2, 2]
    assert change["eye_before_change"]["mean"] == pytest.approx(-0.005)
    assert change["eye_before_worse"] == [0, 2]
    assert rows["without_step_sizes"]["seeds"] == []
    text = markdown(result)
    assert "(+0.35, worse on 2/2)" in text and "(−0.005, worse on 0/2)" in text


def test_a_missing_folder_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([str(tmp_path / "nowhere"), "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "nowhere" in line
    assert not (tmp_path / "out").exists()
