"""The online-error trace replays a run's distance learner: for the run's own settings its last
windowed error is the run's reported one, and other settings change it."""

from __future__ import annotations

import json

import pytest

from parallax.tools.analysis.online_errors import main, trace


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(tmp_path_factory.mktemp("run"), ["train.presentations=8"])


def test_the_trace_ends_at_the_runs_own_online_error(run):
    summary = json.loads((run / "summary.json").read_text())
    rows = trace(run)
    assert len(rows) == 8 - 3  # every presentation after the queue of c = 3 filled
    assert rows[-1]["window_total_pct"] == pytest.approx(summary["distance_error"]["total"])
    assert all(r["fit_rmse_m"] is not None and len(r["s_deg"]) == 2 for r in rows[1:])


def test_other_settings_give_other_predictions(run):
    ours = [r["predicted_m"] for r in trace(run)]
    plain = [r["predicted_m"] for r in trace(run, ["distance.lm.weight_decay=0"])]
    assert ours != plain


def test_the_command_prints_each_combination_and_refuses_a_non_run(run, tmp_path, capsys):
    main([str(run), "distance.lm.weight_decay=0,0.1", "--out", str(tmp_path / "t.json")])
    out = capsys.readouterr().out
    assert out.count("final windowed error") == 2
    assert set(json.loads((tmp_path / "t.json").read_text())) == {
        "distance.lm.weight_decay=0",
        "distance.lm.weight_decay=0.1",
    }
    with pytest.raises(SystemExit) as exit_info:
        main([str(tmp_path)])
    assert exit_info.value.code == 2
