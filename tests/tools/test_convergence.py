"""python -m parallax.tools.analysis.convergence: phases, trends, learning curve, critic scale."""

from __future__ import annotations

import json
import random

import pytest
from omegaconf import OmegaConf

from parallax.config import compose
from parallax.tools.analysis import convergence


def _run(tmp_path, maes, perturbed_from, scales):
    records = [
        {
            "presentation": i + 1,
            "perturbed": i >= perturbed_from,
            "mae_recent_per_position": {"5": mae, "10": mae / 2},
            "policy_critic_scale": scale,
            "policy_entropy": 1.5,
        }
        for i, (mae, scale) in enumerate(zip(maes, scales))
    ]
    (tmp_path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    return tmp_path


def test_a_falling_phase_moves_and_a_level_one_is_flat(tmp_path):
    falling = [1.0 - 0.01 * i for i in range(50)]
    level = [0.2] * 50
    run = _run(tmp_path, falling + level, 50, [0.1] * 99 + [3.0])
    found = convergence.convergence(run, tail=0.2, flat=0.02, block=25)
    assert found["before"]["presentations"] == 50 and not found["before"]["flat"]
    assert found["before"]["trend"] == pytest.approx(-0.1)  # two blocks of 10, 10 apart
    assert found["after"]["flat"] and found["after"]["mae_recent"] == 0.2
    assert found["after"]["per_position"] == {"5": 0.2, "10": 0.1}
    assert found["critic_peak"] == 3.0 and found["critic_last"] == 3.0
    curve = found["blocks"]
    assert [b["first"] for b in curve] == [1, 26, 51, 76]
    assert curve[0]["mae"] == pytest.approx(sum(falling[:25]) / 25)
    assert [b["perturbed"] for b in curve] == [False, False, True, True]


def test_the_command_prints_a_row_per_run_and_refuses_a_missing_record(tmp_path, capsys):
    run = _run(tmp_path, [0.3] * 10, 5, [0.1] * 10)
    convergence.main([str(run), "--blocks", "5"])
    out = capsys.readouterr().out
    assert f"| {run.name} | 0.300° (flat: +0.000°, 5) |" in out
    assert "mean recent MAE by block" in out
    assert "by lateral position" not in out
    convergence.main([str(run), "--positions"])
    out = capsys.readouterr().out
    assert f"{run.name}, recent MAE by lateral position, before: 5 cm: 0.300°, 10 cm: 0.150°" in out
    with pytest.raises(SystemExit) as stop:
        convergence.main([str(tmp_path / "missing")])
    assert stop.value.code == 2


def test_the_trend_interval_tells_a_falling_tail_from_noise():
    rng = random.Random(0)
    noise = [0.3 + rng.gauss(0, 0.02) for _ in range(400)]
    low, high = convergence.trend_interval(noise[200:], noise[:200], memory=50)
    assert low < 0 < high  # a level tail: the interval holds no trend
    trend = sum(noise[200:]) / 200 - sum(noise[:200]) / 200
    assert (low + high) / 2 == pytest.approx(trend)  # centred on the rule's own trend
    falling = [0.5 - 0.001 * i + rng.gauss(0, 0.02) for i in range(400)]
    low, high = convergence.trend_interval(falling[200:], falling[:200], memory=50)
    assert high < 0  # still falling, beyond the noise
    assert convergence.trend_interval(noise[200:], noise[:200], memory=150) is None  # one piece
    assert convergence.trend_interval(noise[200:], noise[:200], memory=None) is None


def test_the_interval_is_read_with_the_run_s_figure_memory(tmp_path):
    run = _run(tmp_path, [0.3 + 0.01 * (i % 2) for i in range(40)], 40, [0.1] * 40)
    assert convergence.convergence(run)["before"]["trend_interval"] is None  # no config.yaml
    (run / "config.yaml").write_text(OmegaConf.to_yaml(compose(["metrics.summary_trials=2"])))
    assert convergence.figure_memory(run) == 2
    found = convergence.convergence(run)["before"]
    assert found["trend_interval"] == pytest.approx((0.0, 0.0), abs=1e-12)  # every piece alike
    assert "(flat: +0.000° [+0.000, +0.000], 40)" in convergence._cell(found)
