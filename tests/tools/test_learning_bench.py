"""The learning benchmark (parallax.tools.bench.learning) counts what it says, and no speed."""

from __future__ import annotations

import json

import pytest

from parallax.tools.bench import learning

from ..conftest import TINY

# two positions of 4 iterations; the MAE window is 4 trials per position
SMALL = [o for o in TINY if not o.startswith("train.")] + ["metrics.summary_trials=4"]


def test_jittered_presentations_are_shared_out_per_robot() -> None:
    cfg = learning.case_config(4, 0, [*SMALL, "train.start_jitter_presentations=10"])
    assert cfg.train.start_jitter_presentations == 3  # ⌈10/4⌉
    assert cfg.env.robots == 4 and cfg.seed == 0 and cfg.perturbation.start_fraction is None
    assert learning.case_config(1, 0, SMALL).train.start_jitter_presentations is None


def test_cases_stop_when_the_eye_has_learnt_or_the_budget_is_spent() -> None:
    # any eye meets 50° at once, as soon as each position holds 4 trials; none meets 0.001°
    learnt = learning.run([1, 2], [0], 50.0, 10_000, SMALL, progress=False)
    for case in learnt["cases"]:
        assert case["learnt"]
        # 8 iterations per presentation; 4 trials per position take 4 presentations of one robot
        # and 2 of two
        assert case["presentations"] == 4 // case["robots"]
        assert case["robot_iterations"] == 8 * case["presentations"] * case["robots"] == 32
    assert learnt["medians"]["B=2"]["robot_iterations_ratio"] == 1.0
    assert learnt["device"] == "cpu" and isinstance(learnt["device_name"], str)
    spent = learning.run([2], [0, 1], 0.001, 40, SMALL, progress=False)
    assert [c["learnt"] for c in spent["cases"]] == [False, False]
    assert all(c["robot_iterations"] == 48 for c in spent["cases"])  # 3 presentations ≥ 40
    assert spent["medians"]["B=2"]["learnt"] == 0 and spent["medians"]["B=2"]["seeds"] == 2


def test_jittered_trials_count_too() -> None:
    report = learning.run(
        [1], [0], 50.0, 10_000, [*SMALL, "train.start_jitter_presentations=3"], progress=False
    )
    assert report["cases"][0]["presentations"] == 4


@pytest.mark.parametrize(
    ("argument", "message"),
    [("--robots=0", "--robots=[0]"), ("--threshold=0", "--threshold=0.0"), ("--budget=0", "0")],
)
def test_bad_arguments_get_one_line_and_exit_2(
    argument: str, message: str, tmp_path, capsys
) -> None:
    out = tmp_path / "report.json"
    with pytest.raises(SystemExit) as stop:
        learning.main([argument, "--json", str(out)])
    error = capsys.readouterr().err
    assert stop.value.code == 2 and message in error
    assert len(error.strip().splitlines()) == 1 and not out.exists()


def test_a_written_report_prints_again(tmp_path, capsys) -> None:
    report = learning.run([1], [0], 50.0, 10_000, SMALL, progress=False)
    path = tmp_path / "report.json"
    path.write_text(json.dumps(report))
    learning.main(["--show", str(path)])
    assert "B=1" in capsys.readouterr().out
