"""The paper's probable scoring of Tables 4–5 beside ours: the network on its own queue at the
end of each phase (summary.json ``distance_error_queue``), and the eye as it trains — the
learning policy on the training photographs — on the grid (parallax-eval ``--split train``,
eval.json ``distance_sampled``); both replayed exactly by parallax-replay."""

from __future__ import annotations

import json

import pytest

from parallax.tools.evaluate import evaluate
from parallax.tools.replay import replay, write_replay


@pytest.fixture(scope="module")
def perturbed_run(tmp_path_factory):
    from tests.conftest import train_tiny_run

    return train_tiny_run(
        tmp_path_factory.mktemp("run"),
        ["train.presentations=8", "perturbation=rotate_blur", "perturbation.start_fraction=0.5"],
    )


def test_each_phase_ends_with_the_network_scored_on_its_queue(perturbed_run):
    summary = json.loads((perturbed_run / "summary.json").read_text())
    for phase in (summary, summary["before_perturbation"]):
        queue = phase["distance_error_queue"]
        assert set(queue) == {"3-4.9", "5-6.9", "7-10", "total"}
        assert queue["total"] >= 0.0
    assert summary["distance_error_queue"] != summary["before_perturbation"]["distance_error_queue"]
    replayed = replay(perturbed_run)["summary"]
    assert json.dumps(replayed["distance_error_queue"]) == json.dumps(
        summary["distance_error_queue"]
    )
    assert json.dumps(replayed["before_perturbation"]["distance_error_queue"]) == json.dumps(
        summary["before_perturbation"]["distance_error_queue"]
    )


def test_the_trained_eye_on_the_grid_is_scored_from_the_sampled_policy(perturbed_run, tmp_path):
    result = evaluate(
        perturbed_run,
        out=tmp_path / "paper",
        distances=[3.5, 5.5, 8.0],
        between=[],
        split="train",
        start_jitter="off",
    )
    sampled, greedy = result["distance_sampled"], result["distance"]
    assert sampled["samples"]["distances"] == [3.5, 5.5, 8.0]
    assert sampled["samples"]["pans"] != greedy["samples"]["pans"]  # the policy's draws
    assert sampled["by_range"] != greedy["by_range"]
    # parallax-replay rescores it on the same eye movements: as trained, the same numbers
    eval_dir = perturbed_run / "paper_eval"
    eval_dir.mkdir()
    (eval_dir / "eval.json").write_text((tmp_path / "paper" / "eval.json").read_text())
    try:
        replayed = replay(perturbed_run)
        rescored = replayed["evals"]["paper_eval/eval.json"]["distance_sampled"]["by_range"]
        assert json.dumps(rescored) == json.dumps(sampled["by_range"])
        write_replay(replayed, tmp_path / "replayed")
        written = json.loads((tmp_path / "replayed" / "paper_eval" / "eval.json").read_text())
        assert "distance_sampled" in written
    finally:
        (eval_dir / "eval.json").unlink()
        eval_dir.rmdir()
