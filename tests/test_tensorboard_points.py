"""TensorBoard keeps every presentation's point across resumes, reruns and a step back."""

from __future__ import annotations

import json

from tests.conftest import train_tiny_run


def _scalar_steps(run_dir, tag: str) -> list[int]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run_dir / "tb"), size_guidance={"scalars": 0}).Reload()
    return [event.step for event in events.Scalars(tag)]


def test_every_presentation_has_one_point_after_resumes_and_reruns(tmp_path):
    run = tmp_path / "run"
    train_tiny_run(run, ["train.presentations=4"])
    train_tiny_run(run, ["train.presentations=6"])  # first resume: 5 and 6
    # second resume, from the checkpoint before the last (presentation 4): TensorBoard must
    # drop the first 5 and 6 and keep their second writing only
    train_tiny_run(run, ["train.presentations=8", "train.resume_from=previous"])
    train_tiny_run(run, ["train.presentations=8"])  # a rerun of the finished run
    records = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["presentation"] for r in records] == list(range(1, 9))
    expected = [r["steps"] for r in records]
    for tag in ("pursuit/mae", "pursuit/mae_recent", "coder/reward"):
        assert _scalar_steps(run, tag) == expected, tag
