"""What the eye allows (parallax.tools.analysis.eye_bound): the estimators fitted to an
evaluation's own eye movements, and the action grid's floor."""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from parallax.config import compose
from parallax.tools.analysis import eye_bound
from tests.conftest import TINY

DISTANCES = [3.0 + 0.25 * i for i in range(29)]  # 3.0 … 10.0 m


def _eval_dir(tmp_path, pans_of, name="eval"):
    """A run folder (the TINY config) holding an eval.json whose greedy eye reached
    ``pans_of(perfect pans)``."""
    run = tmp_path / name
    run.mkdir()
    cfg = compose(TINY)
    (run / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    laterals = tuple(float(l) for l in cfg.curriculum.lateral_positions)
    pans = pans_of(eye_bound.perfect_pans(laterals, tuple(DISTANCES)))
    (run / "eval.json").write_text(
        json.dumps(
            {
                "run_dir": str(run),
                "readout": "best_reward",
                "distance": {"by_range": {"total": 9.99}},
                "greedy_samples": {"grid": {"distances": DISTANCES}},
                "greedy_samples_by_readout": {"best_reward": {"grid": {"pans": pans.tolist()}}},
            }
        )
    )
    return run


def test_the_action_grid_is_the_common_step_of_the_increments():
    assert eye_bound.action_grid_step([-0.2, -0.1, -0.05, 0.0, 0.05, 0.1, 0.2]) == 0.05
    assert eye_bound.action_grid_step([-0.3, 0.0, 0.2]) == 0.1


def test_an_eye_on_the_action_grid_is_at_the_floor_and_a_scattered_eye_is_worse(tmp_path):
    step = 0.05
    on_grid = eye_bound.eye_bound(_eval_dir(tmp_path, lambda p: np.round(p / step) * step))
    noise = np.random.default_rng(0).normal(0.0, 0.1, (len(DISTANCES), 2))
    scattered = eye_bound.eye_bound(_eval_dir(tmp_path, lambda p: p + noise, "scattered"))
    assert on_grid["trials"] == len(DISTANCES) and on_grid["network"] == 9.99
    assert on_grid["lines_on_this_eye"] == pytest.approx(on_grid["floor"])
    assert scattered["floor"] == pytest.approx(on_grid["floor"])
    assert scattered["lines_on_this_eye"] > 3 * on_grid["lines_on_this_eye"]
    assert scattered["network_on_this_eye"] > on_grid["lines_on_this_eye"]
    assert 0 < on_grid["floor"] < 5


def test_a_folder_without_an_eval_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        eye_bound.main([str(tmp_path)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no eval.json" in err[0]


def test_the_worst_presentation_is_the_networks_largest_error_with_the_eyes_largest_miss(
    tmp_path,
):
    worst = 5  # the eye stops 0.8° short at the second lateral position of this presentation

    def stops_short(perfect):
        pans = perfect.copy()
        pans[worst, 1] -= 0.8
        return pans

    run = _eval_dir(tmp_path, stops_short)
    result = json.loads((run / "eval.json").read_text())
    errors = np.full(len(DISTANCES), 1.0)
    errors[worst] = 50.0
    result["distance"]["per_distance"] = {f"{d:.2f}": e for d, e in zip(DISTANCES, errors)}
    (run / "eval.json").write_text(json.dumps(result))
    row = eye_bound.eye_bound(run)
    laterals = compose(TINY).curriculum.lateral_positions
    assert row["worst_distance_m"] == DISTANCES[worst] and row["worst_error"] == 50.0
    assert row["worst_eye_miss_deg"] == pytest.approx(0.8)
    assert row["worst_eye_miss_at_cm"] == pytest.approx(laterals[1] * 100)


def test_the_eyes_failures_are_counted_and_left_out_of_the_networks_other_error(tmp_path):
    failed = (2, 9)  # the eye ends 1.5° and 3° off at one position of these presentations

    def two_failures(perfect):
        pans = perfect.copy()
        pans[failed[0], 0] += 1.5
        pans[failed[1], 1] -= 3.0
        pans[0, 0] += 0.5  # off, but by less than the threshold
        return pans

    run = _eval_dir(tmp_path, two_failures)
    result = json.loads((run / "eval.json").read_text())
    errors = np.full(len(DISTANCES), 2.0)
    errors[list(failed)] = 80.0
    errors[0] = 4.0
    result["distance"]["per_distance"] = {f"{d:.2f}": e for d, e in zip(DISTANCES, errors)}
    (run / "eval.json").write_text(json.dumps(result))
    row = eye_bound.eye_bound(run)
    assert row["miss_deg"] == eye_bound.FAILED_MISS_DEG
    assert row["eye_failures"] == 2 and row["network_median"] == 2.0
    kept = np.delete(errors, list(failed))
    assert row["network_without_failures"] == pytest.approx(kept.mean())
    strict = eye_bound.eye_bound(run, miss_deg=0.4)  # now the 0.5° miss fails too
    assert strict["eye_failures"] == 3
    assert strict["network_without_failures"] == pytest.approx(2.0)


def test_a_miss_threshold_that_is_not_positive_is_one_line_and_exit_2(tmp_path, capsys):
    run = _eval_dir(tmp_path, lambda p: p)
    with pytest.raises(SystemExit) as exit_:
        eye_bound.main([str(run), "--miss", "0"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--miss" in err[0]


def test_it_finds_the_run_from_another_working_directory(tmp_path, monkeypatch, capsys):
    """eval.json from older evaluations stored the run relative to where parallax-eval ran;
    evaluations written into a subfolder of the run (--out RUN/eval_before) find it above."""
    run = _eval_dir(tmp_path, lambda p: p)
    result = json.loads((run / "eval.json").read_text())
    before = run / "eval_before"
    before.mkdir()
    (before / "eval.json").write_text(json.dumps({**result, "run_dir": "outputs/runs/gone"}))
    (run / "eval.json").write_text(json.dumps({**result, "run_dir": "outputs/runs/gone"}))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    eye_bound.main([str(run), str(before)])
    assert capsys.readouterr().out.count("| 29 |") == 2
    (run / "config.yaml").unlink()
    with pytest.raises(SystemExit) as exit_:
        eye_bound.main([str(run)])
    assert exit_.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "outputs/runs/gone" in line
