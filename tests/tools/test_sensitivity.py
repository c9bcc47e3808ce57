"""python -m parallax.tools.analysis.sensitivity: runs sorted into the rows of the sensitivity
study by their settings, and their cells read from their summaries."""

from __future__ import annotations

import json
import shutil

import pytest

from parallax.config import compose
from parallax.health import DIVERGED_NAME, Health
from parallax.tools.analysis import sensitivity
from parallax.trainer import Trainer
from tests.conftest import TINY

#: A shrunken study: the tiny settings, and a perturbation halfway through 4 presentations.
SHRUNK = [*TINY, "train.presentations=4", "train.checkpoint_every=4"]


def _train(run_dir, overrides):
    trainer = Trainer(compose(overrides), run_dir)
    try:
        trainer.fit()
    finally:
        trainer.exp.close()


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("study")
    _train(root / "lineage", ["experiment=sensitivity_single_5", *SHRUNK])
    _train(root / "xi_1", ["experiment=sensitivity_single_5", "+open_setting=xi_1", *SHRUNK])
    # settings of no row: another ξ
    _train(root / "other", ["experiment=sensitivity_single_5", "policy.discount=0.5", *SHRUNK])
    return root


def test_runs_go_to_the_row_of_their_settings(study, tmp_path, capsys):
    out = tmp_path / "table.json"
    args = [str(study), "--json", str(out)] + [f"--override={o}" for o in SHRUNK]
    result = sensitivity.main(args)
    rows = result["table"]["single_5"]
    assert list(rows) == ["lineage", "ξ = 1"]
    summary = json.loads((study / "lineage" / "summary.json").read_text())
    before = summary["before_perturbation"]["last_trials"]
    want = sum(cell["mean"] for cell in before.values()) / len(before)
    # one seed: a mean and no spread
    assert rows["lineage"]["eye_before"] == {"mean": pytest.approx(want), "sd": None, "n": 1}
    assert rows["ξ = 1"]["critic_peak"]["mean"] > 0
    assert [entry.split(":")[0] for entry in result["left_out"]] == [str(study / "other")]
    assert json.loads(out.read_text())["table"]["single_5"].keys() == rows.keys()
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("| lineage |"))
    assert line.startswith(f"| lineage | 1 | — | {want:.3f} |")


def test_a_replays_critic_peak_is_read_from_its_source(study, tmp_path):
    """A replay's compacted record keeps only its distance learner's keys: its row's critic
    peak is its source's, read from the source's record."""
    from parallax.tools.replay import main as replay
    from parallax.tools.report.compact import compact

    replays = tmp_path / "replays"
    replay([str(study / "lineage"), "--out", str(replays), "distance.warm_start=false"])
    compact([replays], keep="distance")
    result = sensitivity.sensitivity([study, replays], SHRUNK)
    rows = result["table"]["single_5"]
    replayed = next(row for row in rows if "warm_start" in row or "new network" in row)
    assert rows[replayed]["critic_peak"] == rows["lineage"]["critic_peak"]
    assert rows[replayed]["critic_peak"]["mean"] > 0


def _stopped_copy(study, root, name, diverged):
    """A copy of the lineage's run that stopped before its summary: killed, or (``diverged``)
    stopped after the perturbation as the trainer stops one whose numbers are not finite, its
    last two records with an infinite critic norm and the trainer's diverged.json; the first of
    those two presentations."""
    run = root / name
    shutil.copytree(study / "lineage", run)
    summary = json.loads((run / "summary.json").read_text())
    (run / "summary.json").unlink()
    records = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    if diverged:
        health = Health(critic_scale_warning=100.0, stop_after_non_finite=2)
        for record in records[-2:]:
            record["policy_critic_norm"], record["policy_critic_scale"] = float("inf"), 1e31
            health.check(record, skipped_total=0, fitted=False)
        assert health.must_stop
        stop = health.stop_record(records[-1]["presentation"], kept=None)
        # the trainer's mark of a run that diverged after the perturbation
        stop["before_perturbation"] = summary["before_perturbation"]
        (run / DIVERGED_NAME).write_text(json.dumps(stop))
    (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    return records[-2]["presentation"]


def test_a_run_stopped_by_non_finite_numbers_counts_as_diverged(study, tmp_path, capsys):
    root = tmp_path / "study"
    shutil.copytree(study / "lineage", root / "lineage")
    at = _stopped_copy(study, root, "diverged", diverged=True)
    _stopped_copy(study, root, "killed", diverged=False)  # unfinished, not diverged: left out
    result = sensitivity.main([str(root)] + [f"--override={o}" for o in SHRUNK])
    lineage = result["table"]["single_5"]["lineage"]
    assert lineage["diverged"] == [at]
    # the diverged run has figures before the perturbation, none after
    assert lineage["eye_before"]["n"] == 2 and lineage["eye_after"]["n"] == 1
    assert lineage["critic_peak"]["n"] == 2 and lineage["critic_peak"]["mean"] > 1e30
    assert [entry.split(":")[0] for entry in result["left_out"]] == [str(root / "killed")]
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("| lineage |"))
    assert line.startswith(f"| lineage | 2 | presentation {at} |")


def test_an_unwritable_json_is_one_line_and_exit_2(study, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(SystemExit) as exit_info:
        sensitivity.main([str(study), "--json", str(blocker / "table.json")])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.count("\n") == 1
