"""python -m parallax.tools.analysis.time_to_learn: the first presentation with a recent MAE ≤
target everywhere."""

from __future__ import annotations

import json

import numpy as np
import pytest

from parallax.tools.analysis import time_to_learn as ttl


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(tmp_path_factory.mktemp("run"), ["train.presentations=5"])


def test_recomputed_targets_agree_with_the_trainers_log(tiny_run, tmp_path):
    logged = ttl.recent_mae_per_position(tiny_run, trials=100)
    assert [r["presentation"] for r in logged] == [1, 2, 3, 4, 5]
    # the same run without the logged per-position MAEs (as written before they were logged)
    stripped = tmp_path / "old"
    stripped.mkdir()
    (stripped / "config.yaml").write_text((tiny_run / "config.yaml").read_text())
    lines = [json.loads(l) for l in (tiny_run / "metrics.jsonl").read_text().splitlines()]
    for line in lines:
        del line["mae_recent_per_position"]
    (stripped / "metrics.jsonl").write_text("".join(json.dumps(l) + "\n" for l in lines))
    recomputed = ttl.recent_mae_per_position(stripped, trials=100)
    for a, b in zip(logged, recomputed):
        assert a["mae"].keys() == b["mae"].keys()
        for k in a["mae"]:
            assert b["mae"][k] == pytest.approx(a["mae"][k], abs=1e-9)


def test_threshold_decides_and_needs_enough_trials(tiny_run):
    worst = max(ttl.recent_mae_per_position(tiny_run, trials=2)[-1]["mae"].values())
    reached = ttl.time_to_learn(tiny_run, threshold=worst + 10.0, trials=2)
    assert reached["presentation"] == 2 and reached["steps"] > 0  # the first with 2 trials each
    assert reached["wall_time_s"] is not None and reached["wall_time_s"] > 0
    never = ttl.time_to_learn(tiny_run, threshold=1e-9, trials=2)
    assert never["presentation"] is None and never["worst_position_at_end"][
        "mae_deg"
    ] == pytest.approx(worst)


def test_a_run_copied_without_its_tensorboard_folder_has_no_wall_time(tiny_run, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(tiny_run, copy, ignore=shutil.ignore_patterns("tb"))
    worst = max(ttl.recent_mae_per_position(copy, trials=2)[-1]["mae"].values())
    reached = ttl.time_to_learn(copy, threshold=worst + 10.0, trials=2)
    assert reached["presentation"] == 2 and reached["wall_time_s"] is None


def test_cli_refuses_bad_input(tiny_run, tmp_path, capsys):
    assert ttl.main([str(tiny_run), "--threshold", "0"]) == 2
    assert "--threshold must be > 0" in capsys.readouterr().err
    assert ttl.main([str(tmp_path)]) == 2
    assert "no metrics.jsonl" in capsys.readouterr().err
    assert ttl.main([str(tiny_run), "--threshold", "100", "--trials", "1"]) == 0
    assert "after presentation 1" in capsys.readouterr().out


def test_spread_mean_is_the_tables_mean_and_counts_runaways(tiny_run):
    spread = ttl.last_trials_spread(tiny_run, trials=3, runaway_deg=0.0)
    recent = ttl.recent_mae_per_position(tiny_run, trials=3)[-1]["mae"]
    assert spread.keys() == recent.keys()
    for k, v in spread.items():
        assert v["mean"] == pytest.approx(recent[k]) and v["trials"] == 3
        assert v["runaway_share"] == 1.0  # every trial is off by more than 0°
    none_off = ttl.last_trials_spread(tiny_run, trials=3, runaway_deg=1e9)
    assert all(v["runaway_share"] == 0.0 for v in none_off.values())
    assert all(np.isnan(v["past_share"]) for v in none_off.values())
    # which way each trial went, from the logged pans and the world's α*
    table = ttl.trial_errors(tiny_run)
    past = (table["pans"] - table["targets"])[-3:] * np.sign(table["targets"][-3:])
    for p, v in enumerate(spread.values()):
        assert v["past_share"] == pytest.approx((past[:, p] > 0).mean())
        assert v["runaway_signed_mean"] == pytest.approx(past[:, p].mean())


def test_pooled_spread_is_over_every_runs_last_trials(tiny_run, tmp_path, capsys):
    single = ttl.last_trials_spread(tiny_run, trials=3)
    twice = ttl.pooled_spread([tiny_run, tiny_run], trials=3)
    for k, v in twice.items():  # the same trials twice: same statistics, twice the count
        assert v["mean"] == pytest.approx(single[k]["mean"]) and v["trials"] == 6
        assert v["median"] == pytest.approx(single[k]["median"])
    out = tmp_path / "pooled.json"
    assert (
        ttl.main([str(tiny_run), str(tiny_run), "--trials", "3", "--pooled", "--json", str(out)])
        == 0
    )
    assert "all 2 runs together:" in capsys.readouterr().out
    assert json.loads(out.read_text())["pooled"].keys() == single.keys()
    # runs of other lateral positions are refused, in one line
    other = tmp_path / "other"
    other.mkdir()
    (other / "config.yaml").write_text(
        (tiny_run / "config.yaml").read_text().replace("- 0.1", "- 0.15")
    )
    (other / "metrics.jsonl").write_text((tiny_run / "metrics.jsonl").read_text())
    with pytest.raises(ValueError, match="lateral positions"):
        ttl.pooled_spread([tiny_run, other], trials=3)


def test_learning_curve_counts_robot_iterations_and_plots(tiny_run, tmp_path):
    curve = ttl.learning_curve(tiny_run, trials=2)
    steps = [r["steps"] for r in ttl.recent_mae_per_position(tiny_run, trials=2)]
    assert curve["robots"] == 1 and curve["robot_iterations"] == steps
    assert len(curve["worst_mae_deg"]) == len(steps) == len(curve["wall_time_s"])
    out = tmp_path / "curves.png"
    assert ttl.main([str(tiny_run), "--trials", "2", "--curves", str(out)]) == 0
    assert out.stat().st_size > 1000


def test_batched_robots_fill_the_window_b_trials_per_presentation(tmp_path):
    from tests.conftest import train_tiny_run

    run = train_tiny_run(tmp_path / "b2", ["env.robots=2", "train.presentations=3"])
    # 2 robots: 4 trials per position after 2 presentations
    assert ttl.time_to_learn(run, threshold=1e9, trials=4)["presentation"] == 2
    assert (
        ttl.learning_curve(run, trials=4)["robot_iterations"][0]
        == 2 * ttl.recent_mae_per_position(run)[0]["steps"]
    )
