"""The analyses of the two future works (parallax.tools.analysis.embodied and .movement) on a
shrunk supervised run with its parallax-eval: every table cell is the replay it names, the
pages and figures are written, and bad input is one line and exit code 2."""

from __future__ import annotations

import json

import pytest

from parallax.tools.analysis import embodied, movement
from parallax.tools.evaluate import evaluate
from parallax.tools.replay import replay
from tests.conftest import train_tiny_run

LATERAL = "curriculum.lateral_positions=[0.05,0.1,0.15,0.2]"


@pytest.fixture(scope="module")
def evaluated_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("analyses") / "supervised"
    train_tiny_run(run, [LATERAL, "distance.queue_size=4", "train.presentations=12"])
    evaluate(run, distances=[3.0, 5.0, 7.0, 9.0], between=[4.2])
    return run


def test_the_embodied_table_cells_are_the_replays_they_name(evaluated_run, tmp_path):
    out, cache = tmp_path / "out", tmp_path / "cache"
    assert embodied.main([str(evaluated_run), "--out", str(out), "--cache", str(cache)]) == 0
    results = json.loads((out / "embodied.json").read_text())
    cells = [r for r in results["rows"] if r["targets"] == "odometry"]
    assert len(cells) == len(embodied.FRACTIONS) * len(embodied.SLIPS)
    cell = next(r for r in cells if r["walk_fraction"] == 0.3 and r["stride_slip"] == 0.02)
    assert "distance.fit_from=1" in cell["overrides"]  # round(0.3 · 4)
    again = embodied.eval_scores(replay(evaluated_run, cell["overrides"]), embodied.FINAL_EVAL)
    assert again == cell["final"]
    page = (out / "README.md").read_text()
    assert "| 30% |" in page and "supervisor" in page and (out / "growth_recovery.png").is_file()
    # a second call reuses the kept replays and writes the same results
    assert embodied.main([str(evaluated_run), "--out", str(out), "--cache", str(cache)]) == 0
    assert json.loads((out / "embodied.json").read_text()) == results


def test_recovery_counts_the_presentations_until_the_error_is_back():
    level = [(p, 1.01, 1.0) for p in range(1, 41)]  # 1 % before the spurt at 40
    jump = [(p, 1.2, 1.0) for p in range(41, 61)]  # 20 % for 20 presentations
    back = [(p, 1.01, 1.0) for p in range(61, 121)]
    result = embodied.recovery(level + jump + back, 40)
    assert result["before_pct"] == pytest.approx(1.0)
    assert result["peak_pct"] == pytest.approx(20.0)
    # the first window of 20 whose mean is ≤ 1.2 % holds no jump: it starts at presentation 61
    assert result["presentations_to_recover"] == 21


def test_the_movement_curve_and_fixed_points(evaluated_run, tmp_path):
    out = tmp_path / "movement"
    assert movement.main([str(evaluated_run), "--out", str(out), "--prices", "0", "1e6"]) == 0
    (result,) = json.loads((out / "movement.json").read_text())["replayed"]
    cheap, dear = result["planner"]
    assert dear["eye_movements"] == 4  # a price no error can pay: one trial of t_h = 4
    assert cheap["eye_movements"] >= dear["eye_movements"]
    assert result["fixed_estimator"]["5-20"]["eye_movements"] == 16
    assert (out / "README.md").is_file() and (out / "error_vs_movement.png").is_file()


@pytest.mark.parametrize("analysis", [embodied, movement])
def test_a_folder_without_runs_is_one_line_and_exit_2(analysis, tmp_path, capsys):
    assert analysis.main([str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
