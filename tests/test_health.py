"""Numerical health (parallax/health.py): a diverging critic is named once; numbers that stop
being finite hold the checkpoints back and stop the run with one line after
train.stop_after_non_finite presentations, its last good checkpoint kept; with null the run goes
on."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys

import pytest

from parallax import checkpoint
from parallax.health import DIVERGED_NAME, Health
from parallax.tools.report.compact import compact
from parallax.tools.report.runs import load_run
from tests.conftest import TINY, train_tiny_run

#: A critic step size that drives the tiny run's critic past every bound, then to overflow.
DIVERGING = [*TINY, "train.presentations=8", "train.checkpoint_every=1", "policy.critic_lr=30"]


def _record(presentation: int, **values) -> dict:
    return {"presentation": presentation, "policy_critic_scale": 1.0, **values}


def test_the_critic_warning_comes_once():
    health = Health(critic_scale_warning=100, stop_after_non_finite=3)
    assert health.check(_record(1, policy_critic_scale=99.0), 0, False) == []
    [line] = health.check(_record(2, policy_critic_scale=150.0), 0, False)
    assert line.startswith("presentation 2: the critic's scale, mean |v·φ|, reached 150, above 100")
    assert health.check(_record(3, policy_critic_scale=1e9), 0, False) == []
    assert health.healthy  # a large critic is named, not stopped at


def test_non_finite_numbers_stop_after_the_streak_and_a_finite_one_resets_it():
    health = Health(critic_scale_warning=100, stop_after_non_finite=2)
    [line] = health.check(_record(1, policy_advantage_norm=math.inf), 0, False)
    assert "numbers stopped being finite (policy_advantage_norm=inf)" in line
    assert not health.healthy and not health.must_stop
    assert health.check(_record(2), 0, False) == [] and health.healthy
    health.check(_record(3), 4, False)  # the policy skipped 4 updates in this presentation
    assert health.problems == "4 policy updates skipped"
    assert health.check(_record(4), 5, False) == [] and health.must_stop  # said once per streak
    message = health.stop_message(4, None)
    assert "have not been finite for 2 presentations" in message
    assert "(1 policy update skipped); no checkpoint was written before it;" in message


def test_the_distance_learner_counts_once_it_fits_and_null_runs_on():
    health = Health(critic_scale_warning=100, stop_after_non_finite=None)
    before_first_fit = _record(1, lm_trained=0.0, lm_loss=math.nan, lm_stopped_non_finite=0.0)
    assert health.check(before_first_fit, 0, fitted=False) == [] and health.healthy
    stopped = _record(2, lm_trained=1.0, lm_loss=math.nan, lm_stopped_non_finite=1.0)
    [line] = health.check(stopped, 0, fitted=True)
    assert "lm_loss=nan, the distance fit met a non-finite Jacobian" in line
    assert line.endswith("running on (train.stop_after_non_finite=null)")
    for _ in range(3, 10):
        health.check(stopped, 0, fitted=True)
    assert not health.must_stop


def test_a_run_driven_to_overflow_stops_with_one_line_and_keeps_its_last_good_checkpoint(
    tmp_path,
):
    run = tmp_path / "run"
    # §5's perturbation at presentation 2, before the numbers stop being finite
    perturbed = [*DIVERGING, "perturbation=rotate_blur", "perturbation.start_fraction=0.25"]
    command = [sys.executable, "-m", "parallax.train", *perturbed, f"hydra.run.dir={run}"]
    proc = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    warnings = [line for line in proc.stderr.splitlines() if "warning:" in line]
    assert len([w for w in warnings if "the critic's scale" in w]) == 1, warnings
    assert len([w for w in warnings if "numbers stopped being finite" in w]) == 1, warnings
    errors = [line for line in proc.stderr.splitlines() if line.startswith("parallax-train:")]
    assert len(errors) == 1, proc.stderr
    stop = re.match(
        r"parallax-train: error: stopped at presentation (\d+): its numbers have not been finite "
        r"for 3 presentations in a row \(.+\); its last good checkpoint, (.+) \(presentation "
        r"(\d+)\), is kept; .* train\.stop_after_non_finite=null$",
        errors[0],
    )
    assert stop, errors[0]
    stopped_at, path, kept = int(stop.group(1)), stop.group(2), int(stop.group(3))
    assert path == str(run / checkpoint.CHECKPOINT_NAME)
    # the streak began after the kept checkpoint: no checkpoint was written during it
    assert kept == stopped_at - 3
    assert checkpoint.read(run / checkpoint.CHECKPOINT_NAME)["presentation"] == kept
    assert not (run / "summary.json").exists()
    # the run is over: its diverged.json says where, the reports and compaction read it so
    stop = json.loads((run / DIVERGED_NAME).read_text())
    assert (stop["stopped_at"], stop["unhealthy_since"]) == (stopped_at, kept + 1)
    assert stop["last_checkpoint"] == kept and f"({stop['problems']})" in errors[0]
    assert stop["before_perturbation"]["presentations"] == 2
    loaded = load_run(run)
    assert loaded.diverged == stop and loaded.problem.startswith("diverged: stopped at")
    assert loaded.last_trials("before") == stop["before_perturbation"]["last_trials"]
    assert loaded.last_trials("after") is None
    assert compact([run])[:2] == (1, 1) and (run / "metrics.jsonl.xz").is_file()

    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run / "tb"), size_guidance={"tensors": 0}).Reload()
    assert "health/text_summary" in events.Tags()["tensors"]
    # the critic's line, the first non-finite presentation's, the stop
    assert len(events.Tensors("health/text_summary")) == 3


def test_a_diverged_run_that_goes_on_from_its_checkpoint_is_no_longer_over(tmp_path):
    run = tmp_path / "run"
    (run / DIVERGED_NAME).parent.mkdir()
    (run / DIVERGED_NAME).write_text("{}")  # an earlier stop's mark
    run = train_tiny_run(run, ["train.presentations=2"])
    assert (run / "summary.json").is_file() and not (run / DIVERGED_NAME).exists()


def test_with_null_a_diverging_run_goes_on_to_the_end(tmp_path, capsys):
    run = train_tiny_run(
        tmp_path / "run",
        [*DIVERGING[len(TINY) :], "train.presentations=6", "train.stop_after_non_finite=null"],
    )
    assert (run / "summary.json").is_file()
    assert checkpoint.read(run / checkpoint.CHECKPOINT_NAME)["presentation"] == 6
    err = capsys.readouterr().err
    assert err.count("numbers stopped being finite") == 1
    assert "running on (train.stop_after_non_finite=null)" in err


@pytest.mark.parametrize(
    "override, named",
    [
        ("train.stop_after_non_finite=0", "train.stop_after_non_finite=0"),
        ("train.critic_scale_warning=-1", "train.critic_scale_warning=-1.0"),
        ("train.critic_scale_warning=nan", "train.critic_scale_warning=nan"),
        ("train.resume_from=oldest", "train.resume_from=oldest"),
    ],
)
def test_bad_health_and_resume_settings_are_named(override, named):
    from parallax.train import check_command_line

    line = check_command_line([override])
    assert line is not None and line.startswith(named + ": "), line
