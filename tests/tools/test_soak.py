"""The soak (parallax/tools/bench/soak.py) on a tiny budget: it trains at least the robot-
iterations asked for and counts what the health checks watch; its figures from records."""

from __future__ import annotations

import json
import math

import pytest

from parallax.tools.bench.soak import main, soak_figures
from tests.conftest import TINY


def test_figures_count_non_finite_values_skips_and_the_peak_critic_scale():
    records = [
        # before the distance learner's first fit its loss is NaN by definition: not counted
        {"presentation": 1, "steps": 8, "reward": -1.0, "policy_critic_scale": 2.0,
         "lm_trained": 0.0, "lm_loss": math.nan},
        {"presentation": 2, "steps": 16, "reward": -1.0, "policy_critic_scale": 150.0,
         "policy_advantage_norm": math.inf, "lm_trained": 1.0, "lm_loss": math.nan,
         "lm_stopped_non_finite": 1.0},
        {"presentation": 3, "steps": 24, "reward": math.nan, "policy_critic_scale": math.nan,
         "lm_trained": 1.0, "lm_loss": 0.1, "lm_stopped_non_finite": 0.0},
    ]  # fmt: skip
    figures = soak_figures(records, robots=2, skipped_updates=7, bound=100.0)
    assert figures["robot_iterations"] == 48
    assert figures["non_finite_by_key"] == {
        "policy_advantage_norm": 1,
        "lm_loss": 1,
        "reward": 1,
        "policy_critic_scale": 1,
    }
    assert figures["non_finite_values"] == 4 and figures["presentations_with_non_finite"] == 2
    assert figures["skipped_policy_updates"] == 7
    assert figures["distance_fits_stopped_non_finite"] == 1
    assert (figures["peak_critic_scale"], figures["peak_critic_scale_presentation"]) == (150.0, 2)
    assert figures["presentations_above_bound"] == 1


def test_a_tiny_soak_runs_its_budget_and_writes_its_report(tmp_path, capsys):
    overrides = [o for o in TINY if not o.startswith("train.presentations")]
    figures = main(["--iterations", "12", "--out", str(tmp_path / "soak"), *overrides])
    # two lateral positions × 4 iterations per presentation: 12 needs two presentations
    assert figures["robot_iterations"] == 16 and figures["presentations"] == 2
    assert figures["non_finite_values"] == 0 and figures["skipped_policy_updates"] == 0
    assert 0 < figures["peak_critic_scale"] < figures["critic_scale_bound"]
    assert json.loads((tmp_path / "soak" / "soak.json").read_text())["robot_iterations"] == 16
    assert "soak: 16 robot-iterations in 2 presentations" in capsys.readouterr().out


def test_a_soak_that_cannot_write_its_folder_is_one_line(tmp_path, capsys):
    (tmp_path / "a_file").write_text("")
    with pytest.raises(SystemExit) as exit_:
        main(["--iterations", "8", "--out", str(tmp_path / "a_file" / "soak")])
    assert exit_.value.code == 2
    [line] = capsys.readouterr().err.splitlines()
    assert line.startswith(f"soak: error: --out {tmp_path / 'a_file' / 'soak'}: lies inside")
