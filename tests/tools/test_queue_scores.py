"""python -m parallax.tools.report.queue_scores: a record that predates the queue scoring gets the
score its own training would have written, from a replay that reproduces its online errors."""

from __future__ import annotations

import json
import shutil

import pytest

from parallax.tools.report import queue_scores
from tests.tools.test_replay import PERTURBED


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(tmp_path_factory.mktemp("run"), PERTURBED)


def _without_queue_scores(trained, tmp_path):
    run = tmp_path / trained.name
    shutil.copytree(trained, run)
    summary = json.loads((run / "summary.json").read_text())
    summary.pop("distance_error_queue")
    summary["before_perturbation"].pop("distance_error_queue")
    (run / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return run


def test_a_run_without_queue_scores_gets_those_its_training_wrote(trained, tmp_path, capsys):
    original = json.loads((trained / "summary.json").read_text())
    assert original["distance_error_queue"]["total"] is not None, "the tiny run must fill its queue"
    run = _without_queue_scores(trained, tmp_path)
    queue_scores.main([str(run)])
    assert "1 summaries completed" in capsys.readouterr().out
    completed = json.loads((run / "summary.json").read_text())
    for phase in (completed, completed["before_perturbation"]):
        wanted = (original if phase is completed else original["before_perturbation"])[
            "distance_error_queue"
        ]
        assert phase["distance_error_queue"] == pytest.approx(wanted, rel=1e-9)
    assert completed["distance_error_queue_from"] == queue_scores.MADE_BY
    queue_scores.main([str(run)])  # complete already: left alone
    assert "0 summaries completed" in capsys.readouterr().out


def test_a_run_whose_replay_disagrees_is_refused_and_nothing_changes(trained, tmp_path, capsys):
    run = _without_queue_scores(trained, tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    summary["distance_error"]["total"] += 1.0  # not what its learner made
    text = json.dumps(summary, indent=2) + "\n"
    (run / "summary.json").write_text(text)
    with pytest.raises(SystemExit) as stop:
        queue_scores.main([str(run)])
    assert stop.value.code == 2
    assert "the replay is not this run's learner" in capsys.readouterr().err
    assert (run / "summary.json").read_text() == text
    with pytest.raises(SystemExit) as stop:
        queue_scores.main([str(tmp_path / "missing")])
    assert stop.value.code == 2
    (run / "summary.json").unlink()  # a run still training: left alone
    queue_scores.main([str(run)])
    assert "0 summaries completed" in capsys.readouterr().out
    assert not (run / "summary.json").exists()
