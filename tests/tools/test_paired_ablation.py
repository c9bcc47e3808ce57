"""python -m parallax.tools.report.paired_ablation: an ablation's values against its baseline as
paired differences with intervals, on synthetic runs with a known difference."""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from parallax.config.schema import Config
from parallax.tools.report import paired_ablation as pa


def _run(folder, seed: int, y: float, eye: float, errors: list[float], weighting: bool = True):
    """A finished run without a perturbation: its eye error at two positions and its held-out
    errors photograph by photograph."""
    cfg = OmegaConf.structured(Config)
    cfg.seed, cfg.distance.y, cfg.distance.weighting = seed, y, weighting
    cfg.curriculum.lateral_positions = [0.05, 0.1]
    cfg.perturbation.start_fraction = None
    cfg.train.presentations = 10
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    summary = {
        "presentations": 10,
        "last_trials": {"5": {"mean": eye, "var": 0.0, "trials": 100},
                        "10": {"mean": eye + 0.1, "var": 0.0, "trials": 100}},
        "distance_error": {"total": float(np.mean(errors))},
        "distance_error_queue": {"total": float(np.mean(errors)) / 2},
        "before_perturbation": None,
    }  # fmt: skip
    (folder / "summary.json").write_text(json.dumps(summary))
    grid = [3.0 + 0.1 * k for k in range(len(errors))]
    evaluation = {
        "presentations": 10,
        "perturbed": False,
        "stimuli_overrides": [],
        "distance": {
            "by_range": {"total": float(np.mean(errors))},
            "per_distance": {f"{d:.2f}": e for d, e in zip(grid, errors)},
            "errors": errors,
        },
    }
    (folder / "eval.json").write_text(json.dumps(evaluation))


def test_a_known_improvement_is_told_apart_and_no_change_is_not(tmp_path):
    rng = np.random.default_rng(0)
    for seed in range(4):
        difficulty = rng.gamma(2.0, 2.0, 30)
        base = difficulty + rng.normal(0, 0.3, 30)
        _run(tmp_path / f"y1_{seed}", seed, 1.0, 0.2, (5 + base).tolist())
        _run(tmp_path / f"y2_{seed}", seed, 2.0, 0.2 + 0.01 * seed, (4 + base).tolist())
        noise = rng.normal(0, 0.3, 30)
        _run(tmp_path / f"y4_{seed}", seed, 4.0, 0.2, (5 + difficulty + noise).tolist())
    result = pa.ablation([tmp_path], "distance.y", baseline="1.0")
    rows = {row["value"]: row["measures"] for row in result["rows"]}
    better = rows["2.0"]["held_out_before"]["difference"]
    assert better["mean"] == pytest.approx(-1.0) and better["tells_apart"]
    assert better["samples"] == 4 * 30
    same = rows["4.0"]["held_out_before"]["difference"]
    assert not same["tells_apart"] and same["low"] < 0 < same["high"]
    assert rows["2.0"]["eye_before"]["difference"]["mean"] == pytest.approx(0.015)
    assert rows["2.0"]["queue_before"]["difference"]["mean"] == pytest.approx(-0.5)
    assert "difference" not in rows["1.0"]["held_out_before"]  # the baseline itself
    assert rows["2.0"]["eye_after"]["value"]["n"] == 0  # never perturbed: no "after"
    text = pa.markdown(result)
    assert "| 2.0 | 0, 1, 2, 3 |" in text and "told apart" in text
    # y = 4 has y = 1's eye in every seed, as a replay has: said so, not given as an effect
    (row_4,) = [line for line in text.splitlines() if line.startswith("| 4.0 |")]
    assert row_4.split(" | ")[2].endswith("; the same in every sample")


def test_two_runs_of_one_value_and_seed_or_one_value_only_are_refused(tmp_path, capsys):
    _run(tmp_path / "a", 0, 1.0, 0.2, [1.0, 2.0])
    with pytest.raises(SystemExit) as stop:
        pa.main([str(tmp_path), "--factor", "distance.y"])
    assert stop.value.code == 2 and "fewer than two values" in capsys.readouterr().err
    _run(tmp_path / "b", 0, 1.0, 0.2, [1.0, 2.0])
    with pytest.raises(SystemExit):
        pa.main([str(tmp_path), "--factor", "distance.y"])
    assert "two runs of distance.y=1.0 with seed 0" in capsys.readouterr().err


def test_the_held_out_measure_reads_the_evaluation_with_the_most_photographs(tmp_path):
    from parallax.tools.report.runs import load_run

    folder = tmp_path / "run"
    _run(folder, 0, 1.0, 0.2, [4.0, 5.0])
    more = json.loads((folder / "eval.json").read_text())
    more["textures_per_distance"] = 5
    more["distance"]["errors"] = [1.0] * 10
    (folder / "eval_textures5").mkdir()
    (folder / "eval_textures5" / "eval.json").write_text(json.dumps(more))
    run = load_run(folder)
    # the report reads the run's own evaluation; the ablation, the one with five per distance
    assert run.eval_for("before")["distance"]["errors"] == [4.0, 5.0]
    assert pa.MEASURES["held_out"](run, "before") == [1.0] * 10


def test_a_baseline_scored_on_more_photographs_pairs_on_the_evaluations_both_have(tmp_path):
    """The baseline's runs also have five photographs per distance, the value's one: the pair
    is the runs' own evaluations, trial for trial, not no pair at all."""
    for seed in range(3):
        _run(tmp_path / f"y1_{seed}", seed, 1.0, 0.2, [5.0, 6.0, 7.0])
        _run(tmp_path / f"y2_{seed}", seed, 2.0, 0.2, [4.0, 5.0, 6.0 + 0.1 * seed])
        more = json.loads((tmp_path / f"y1_{seed}" / "eval.json").read_text())
        more["textures_per_distance"] = 5
        more["distance"]["errors"] = [9.0] * 15
        (tmp_path / f"y1_{seed}" / "eval_textures5").mkdir()
        (tmp_path / f"y1_{seed}" / "eval_textures5" / "eval.json").write_text(json.dumps(more))
    result = pa.ablation([tmp_path], "distance.y", baseline="1.0")
    rows = {row["value"]: row["measures"] for row in result["rows"]}
    assert rows["1.0"]["held_out_before"]["value"]["mean"] == pytest.approx(9.0)
    difference = rows["2.0"]["held_out_before"]["difference"]
    assert difference["samples"] == 3 * 3
    assert difference["mean"] == pytest.approx(-1.0 + 0.1 / 3 * (0 + 1 + 2) / 3)


def test_several_settings_make_one_factor_and_name_each_row(tmp_path):
    # the weighting ablation: each y weighted, and no weighting (at the run's y), the baseline
    for seed in range(3):
        _run(tmp_path / f"none_{seed}", seed, 1.0, 0.2, [5.0, 6.0 + seed], weighting=False)
        _run(tmp_path / f"y1_{seed}", seed, 1.0, 0.2, [4.0, 5.0 + seed])
        _run(tmp_path / f"y2_{seed}", seed, 2.0, 0.2, [5.0, 6.0 + seed])
    baseline = "distance.weighting=false, distance.y=1.0"
    result = pa.ablation([tmp_path], "distance.weighting,distance.y", baseline=baseline)
    rows = {row["value"]: row["measures"] for row in result["rows"]}
    assert set(rows) == {
        baseline,
        "distance.weighting=true, distance.y=1.0",
        "distance.weighting=true, distance.y=2.0",
    }
    weighted = rows["distance.weighting=true, distance.y=1.0"]["held_out_before"]["difference"]
    assert weighted["mean"] == pytest.approx(-1.0)
    with pytest.raises(pa.ReportError, match="no setting distance.why"):
        pa.ablation([tmp_path], "distance.weighting,distance.why")


def test_numbers_in_the_values_are_ordered_as_numbers(tmp_path):
    for y in (10.0, 2.0, 0.25, 1.0):
        _run(tmp_path / f"y{y}", 0, y, 0.2, [5.0, 6.0, 7.0])
    result = pa.ablation([tmp_path], "distance.y")
    assert [row["value"] for row in result["rows"]] == ["0.25", "1.0", "2.0", "10.0"]
    assert result["baseline"] == "0.25"  # the first, so ordered
    assert sorted(["c=1000", "c=50", "c=300"], key=pa.natural_order) == ["c=50", "c=300", "c=1000"]
