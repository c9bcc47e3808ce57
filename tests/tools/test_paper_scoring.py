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


def test_the_report_reads_the_trained_eye_apart_from_the_held_out_photographs(perturbed_run):
    from parallax.tools.report.runs import load_run
    from parallax.tools.report.tables import _distance_values

    trained = {}
    for checkpoint, out, phase in (
        ("checkpoint_before_perturbation.pt", "eval_before_trained", "before"),
        ("checkpoint.pt", "eval_trained", "after"),
    ):
        result = evaluate(
            perturbed_run,
            out=perturbed_run / out,
            checkpoint_name=checkpoint,
            distances=[3.5, 5.5, 8.0],
            between=[],
            split="train",
        )
        trained[phase] = result["distance_sampled"]["by_range"]
    held_out = evaluate(perturbed_run, out=perturbed_run / "eval_held_out", distances=[3.5])
    try:
        run = load_run(perturbed_run)
        for phase in ("before", "after"):
            assert run.trained_eye_distance(phase) == trained[phase]
        # the held-out scoring reads the held-out evaluation only, never the training photographs'
        assert json.dumps(run.eval_for("after")["distance"]) == json.dumps(held_out["distance"])
        assert run.eval_for("before") is None

        class OneRun:
            runs = [run]

        values, source = _distance_values(OneRun(), "after", scoring="trained_eye")
        assert values == [trained["after"]] and "--split train" in source
    finally:
        import shutil

        for out in ("eval_before_trained", "eval_trained", "eval_held_out"):
            shutil.rmtree(perturbed_run / out)
