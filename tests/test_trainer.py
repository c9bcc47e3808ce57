"""The trainer end to end on a shrunken config: outputs, determinism, resume after SIGKILL, eval."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from parallax.config import compose
from parallax.readouts.best_reward import BestReward
from parallax.trainer import Trainer


def _train(tmp: Path, overrides: list[str]) -> dict:
    cfg = compose(overrides)
    trainer = Trainer(cfg, tmp)
    try:
        return trainer.fit()
    finally:
        trainer.exp.close()


def _without_timing(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k != "timing"}


def test_run_writes_everything(tmp_path, tiny_overrides):
    from tests.conftest import IMAGES

    summary = _train(tmp_path, [*tiny_overrides, IMAGES])
    lines = (tmp_path / "metrics.jsonl").read_text().splitlines()
    assert len(lines) == 6
    records = [json.loads(line) for line in lines]
    assert [r["presentation"] for r in records] == list(range(1, 7))
    # 2 lateral positions × 4 iterations per presentation
    assert records[-1]["steps"] == 6 * 8
    assert (tmp_path / "checkpoint.pt").is_file()
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(
        str(tmp_path / "tb"), size_guidance={"scalars": 0, "images": 0}
    ).Reload()
    scalars = set(events.Tags()["scalars"])
    assert {
        "coder/reward",
        "coder/error_coarse",
        "coder/error_fine",
        "pursuit/mae",
        "pursuit/mae_5cm",
        "pursuit/mae_10cm",
        "policy/entropy",
        "perf/steps_per_second",
        "distance/error_pct_total",
        "distance/lm_loss",
        "distance/lm_mu",
    } <= scalars, scalars
    assert {"coder/atoms_coarse", "coder/atoms_fine", "world/I0_beside_It"} <= set(
        events.Tags()["images"]
    )
    assert len(events.Scalars("pursuit/mae")) == 6
    assert "pursuit/mae_recent" in scalars
    # mae_window=20 trials, summary_trials=100: after 12 trials both cover every trial so far
    assert records[-1]["mae_recent"] == pytest.approx(records[-1]["mae"])
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["presentations"] == 6 and saved["trials"] == 12
    assert set(saved["mae_per_position"]) == {"5", "10"}
    # the queue (c = 3) fills after 3 presentations; predictions are made for the next ones
    assert set(saved["distance_error"]) >= {"total"}
    assert summary["steps"] == 48


def test_same_seed_same_metrics_other_seed_differs(tmp_path, tiny_overrides):
    a = _train(tmp_path / "a", tiny_overrides + ["seed=3"])
    b = _train(tmp_path / "b", tiny_overrides + ["seed=3"])
    c = _train(tmp_path / "c", tiny_overrides + ["seed=4"])
    assert (tmp_path / "a" / "metrics.jsonl").read_text() == (
        tmp_path / "b" / "metrics.jsonl"
    ).read_text()
    assert _without_timing(a) == _without_timing(b)
    assert _without_timing(a) != _without_timing(c)


@pytest.mark.parametrize(
    "extra",
    [
        [],
        ["policy.feature_norm=difference"],
        # the jitter ends after the resume point: the resumed run must switch it off
        ["env.initial_pan_jitter_deg=1", "train.start_jitter_presentations=5"],
        # the body sweeps L while the eye pursues, each image coded against the one before
        [
            "env.motion=continuous",
            "env.sweep.speed_m=0.01",
            "train.distance_readout=last",
            "coder.pairing=consecutive",
        ],
    ],
    ids=["shipped", "difference", "jitter_until_5", "continuous_consecutive"],
)
def test_resume_in_process_matches_uninterrupted(tmp_path, tiny_overrides, extra):
    # feature_norm=difference adds one (I0, I0) encode per trial; still same seed, same numbers
    tiny_overrides = tiny_overrides + extra
    full = _train(tmp_path / "full", tiny_overrides)
    _train(tmp_path / "part", tiny_overrides + ["train.presentations=4"])
    # continuing the same run directory with the full budget
    resumed = _train(tmp_path / "part", tiny_overrides)
    assert _without_timing(resumed) == _without_timing(full)
    assert (tmp_path / "part" / "metrics.jsonl").read_text() == (
        tmp_path / "full" / "metrics.jsonl"
    ).read_text()


def test_a_finished_run_lengthened_after_its_perturbation_matches_the_longer_run(
    tmp_path, tiny_overrides
):
    # §5's continuation made longer: a 4-presentation run perturbed from presentation 2 on, then
    # the same directory with 6 presentations and the start fraction that keeps presentation 2
    perturbed = tiny_overrides + ["perturbation=rotate_blur"]
    longer = perturbed + ["perturbation.start_fraction=0.3333"]
    full = _train(tmp_path / "full", longer)
    _train(
        tmp_path / "part", perturbed + ["train.presentations=4", "perturbation.start_fraction=0.5"]
    )
    resumed = _train(tmp_path / "part", longer)
    assert _without_timing(resumed) == _without_timing(full)
    assert resumed["before_perturbation"]["presentations"] == 2
    assert (tmp_path / "part" / "metrics.jsonl").read_text() == (
        tmp_path / "full" / "metrics.jsonl"
    ).read_text()


def test_the_phase_before_the_perturbation_lengthened_from_its_checkpoint_matches_the_longer_run(
    tmp_path, tiny_overrides
):
    # A finished run's state just before its perturbation (presentation 2 of 4) continued with a
    # later start (presentation 4 of 8): the run so far is the same under both schedules, so it
    # gives the numbers of the longer run trained from the start
    import shutil

    from parallax import checkpoint

    perturbed = tiny_overrides + ["perturbation=rotate_blur", "perturbation.start_fraction=0.5"]
    longer = perturbed + ["train.presentations=8"]
    full = _train(tmp_path / "full", longer)
    _train(tmp_path / "short", perturbed + ["train.presentations=4"])
    (tmp_path / "part").mkdir()
    shutil.copy(
        tmp_path / "short" / checkpoint.BEFORE_PERTURBATION_NAME,
        tmp_path / "part" / checkpoint.CHECKPOINT_NAME,
    )
    shutil.copy(tmp_path / "short" / "metrics.jsonl", tmp_path / "part" / "metrics.jsonl")
    resumed = _train(tmp_path / "part", longer)
    assert _without_timing(resumed) == _without_timing(full)
    assert resumed["before_perturbation"]["presentations"] == 4
    assert (tmp_path / "part" / "metrics.jsonl").read_text() == (
        tmp_path / "full" / "metrics.jsonl"
    ).read_text()
    # the short run's last checkpoint has seen its perturbation: it cannot move
    with pytest.raises(checkpoint.CheckpointError, match="start presentation.*2 → 4"):
        _train(tmp_path / "short", longer)


def test_the_start_jitter_ends_after_start_jitter_presentations(tmp_path, tiny_overrides):
    _train(
        tmp_path,
        tiny_overrides + ["env.initial_pan_jitter_deg=1", "train.start_jitter_presentations=4"],
    )
    records = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert [r["start_jitter"] for r in records] == [True] * 4 + [False] * 2
    jittered = [p for r in records[:4] for p in r["start_pans"][0]]
    assert all(-1.0 <= p <= 1.0 for p in jittered) and len(set(jittered)) == len(jittered)
    assert all(p == 0.0 for r in records[4:] for p in r["start_pans"][0])  # the paper's start
    # parallax-eval starts its trials as the end of training did, unless told otherwise
    from parallax.tools.evaluate import evaluate

    assert (
        evaluate(tmp_path, distances=[3.0], between=[], out=tmp_path / "e1")["start_jitter"]
        is False
    )
    jittered = evaluate(
        tmp_path, distances=[3.0, 5.0], between=[], out=tmp_path / "e2", start_jitter="on"
    )
    assert jittered["start_jitter"] is True
    split = jittered["mae_by_start"]["sampled"]
    assert 0.0 <= split["share_started_past"] <= 1.0 and split["started_short"] >= 0.0
    with pytest.raises(ValueError, match="--start-jitter must be auto, on or off, got 'yes'"):
        evaluate(tmp_path, distances=[3.0], start_jitter="yes")


def test_mae_by_start_splits_trials_by_the_side_they_started_on():
    from parallax.tools.evaluate import mae_by_start

    # α* = +1° (first robot) and −1° (second, the mirror case); each starts past once and short once
    run = {
        "targets": np.array([[1.0, 1.0], [-1.0, -1.0]]),
        "start_pans": np.array([[1.5, 0.0], [-0.5, -2.0]]),
        "pans": np.array([[3.0, 1.1], [-1.2, -1.0]]),
    }
    split = mae_by_start(run)
    assert split["share_started_past"] == 0.5
    assert split["started_past"] == pytest.approx((2.0 + 0.0) / 2)  # 1.5 and −2.0 started past
    assert split["started_short"] == pytest.approx((0.1 + 0.2) / 2)


def _cli(run_dir: Path, overrides: list[str]) -> list[str]:
    return [sys.executable, "-m", "parallax.train", *overrides, f"hydra.run.dir={run_dir}"]


def test_resume_drops_a_torn_log_line(tmp_path, tiny_overrides):
    _train(tmp_path / "full", tiny_overrides)
    _train(tmp_path / "part", tiny_overrides + ["train.presentations=4"])
    with (tmp_path / "part" / "metrics.jsonl").open("a") as log:
        log.write('{"presentation": 5, "ste')  # a hard kill in the middle of a write
    _train(tmp_path / "part", tiny_overrides)
    assert (tmp_path / "part" / "metrics.jsonl").read_text() == (
        tmp_path / "full" / "metrics.jsonl"
    ).read_text()


def test_a_compacted_run_goes_on_from_its_compressed_log(tmp_path, tiny_overrides):
    from parallax.tools.report.compact import compact

    full = (_train(tmp_path / "full", tiny_overrides), tmp_path / "full" / "metrics.jsonl")
    part = tmp_path / "part"
    _train(part, tiny_overrides + ["train.presentations=4"])
    assert compact([part])[:2] == (1, 1)  # a finished run, committed compressed
    # lengthened: the log goes on from the compressed lines, as one plain file
    _train(part, tiny_overrides)
    assert not (part / "metrics.jsonl.xz").exists()
    assert (part / "metrics.jsonl").read_text() == full[1].read_text()
    # without its checkpoints (as committed), a new start keeps none of the compressed lines
    compact([part])
    for saved in part.glob("*.pt"):
        saved.unlink()
    assert _without_timing(_train(part, tiny_overrides)) == _without_timing(full[0])
    assert not (part / "metrics.jsonl.xz").exists()
    assert (part / "metrics.jsonl").read_text() == full[1].read_text()


def test_a_start_without_a_checkpoint_keeps_no_earlier_log_lines(tmp_path, tiny_overrides):
    # a run stopped before its first checkpoint leaves lines but nothing to resume from
    _train(tmp_path / "full", tiny_overrides)
    (tmp_path / "part").mkdir()
    (tmp_path / "part" / "metrics.jsonl").write_text('{"presentation": 1, "steps": 8}\n')
    _train(tmp_path / "part", tiny_overrides)
    assert (tmp_path / "part" / "metrics.jsonl").read_text() == (
        tmp_path / "full" / "metrics.jsonl"
    ).read_text()


@pytest.mark.slow
def test_sigkill_then_resume_gives_the_same_summary(tmp_path, tiny_overrides):
    overrides = tiny_overrides + ["train.presentations=10", "train.checkpoint_every=1"]
    ref = tmp_path / "ref"
    subprocess.run(_cli(ref, overrides), check=True, capture_output=True, timeout=600, cwd=tmp_path)
    killed = tmp_path / "killed"
    proc = subprocess.Popen(
        _cli(killed, overrides), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path
    )
    deadline = time.time() + 300
    # kill once some presentations are done, somewhere in the middle of the run
    while time.time() < deadline and proc.poll() is None:
        metrics = killed / "metrics.jsonl"
        if metrics.exists() and len(metrics.read_text().splitlines()) >= 4:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be killed; make it longer"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (killed / "summary.json").exists()
    subprocess.run(
        _cli(killed, overrides), check=True, capture_output=True, timeout=600, cwd=tmp_path
    )
    a = json.loads((ref / "summary.json").read_text())
    b = json.loads((killed / "summary.json").read_text())
    assert _without_timing(a) == _without_timing(b)
    assert (ref / "metrics.jsonl").read_text() == (killed / "metrics.jsonl").read_text()


def test_perturbation_switches_on_mid_run(tmp_path, tiny_overrides):
    summary = _train(
        tmp_path, tiny_overrides + ["perturbation=rotate_blur", "perturbation.start_fraction=0.5"]
    )
    records = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    # presentations 1-3 ran unperturbed, 4-6 perturbed
    assert [r["perturbed"] for r in records] == [False, False, False, True, True, True]
    assert summary["before_perturbation"]["presentations"] == 3
    assert (tmp_path / "checkpoint_before_perturbation.pt").is_file()
    from parallax.tools.evaluate import evaluate

    before = evaluate(
        tmp_path,
        distances=[4.0],
        between=[],
        out=tmp_path / "eval_before",
        checkpoint_name="checkpoint_before_perturbation.pt",
    )
    after = evaluate(tmp_path, distances=[4.0], between=[])
    assert before["perturbed"] is False and before["presentations"] == 3
    assert after["perturbed"] is True and after["presentations"] == 6


def test_staged_curriculum_widens_the_list(tmp_path, tiny_overrides):
    overrides = tiny_overrides + [
        "curriculum=staged",
        "curriculum.lateral_positions=[0.05,0.1]",
        "curriculum.stages=[[0.05],[0.05,0.1]]",
        "curriculum.advance_below_deg=100",
        "curriculum.min_trials=2",
    ]
    _train(tmp_path, overrides)
    records = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert records[0]["stage"] == 0 and records[-1]["stage"] == 1
    assert records[-1]["steps"] < 6 * 8  # the first presentations visited one position only


def test_eval_writes_json_and_figures(tmp_path, tiny_overrides):
    from parallax.tools.evaluate import evaluate

    # the run's readout, which evaluate uses by default, is the paper's: the last pan of a trial
    _train(tmp_path, tiny_overrides + ["train.distance_readout=last"])
    result = evaluate(tmp_path, distances=[3.0, 6.5, 10.0], between=[4.25])
    assert set(result["mae_per_position"]) == {"greedy", "sampled"}
    assert (tmp_path / "eval.json").is_file()
    assert (tmp_path / "eval_mae_per_position.png").is_file()
    assert (tmp_path / "mae_curves.png").is_file()
    assert "distance" in result and "total" in result["distance"]["by_range"]
    with pytest.raises(ValueError, match="--device must be cpu or cuda, got 'gpu'"):
        evaluate(tmp_path, distances=[3.0], device="gpu")
    if not torch.cuda.is_available():  # a run trained on a GPU, evaluated here: told what to pass
        config = tmp_path / "config.yaml"
        config.write_text(config.read_text().replace("device: cpu", "device: cuda"))
        with pytest.raises(ValueError, match="pass --device cpu"):
            evaluate(tmp_path, distances=[3.0])
        assert evaluate(tmp_path, distances=[3.0], between=[], device="cpu")["mae"]
        config.write_text(config.read_text().replace("device: cuda", "device: cpu"))
    # beyond the paper: s read where the coder's reward was highest in each trial
    best = evaluate(
        tmp_path,
        distances=[3.0, 6.5, 10.0],
        between=[],
        out=tmp_path / "best",
        readout="best_reward",
    )
    assert best["readout"] == "best_reward" and result["readout"] == "last"
    assert (
        best["greedy_samples"]["grid"]["distances"] == result["greedy_samples"]["grid"]["distances"]
    )
    with pytest.raises(ValueError, match="--readout must be one of last, best_reward, got 'peak'"):
        evaluate(tmp_path, distances=[3.0], readout="peak")


def test_best_pans_are_the_pans_where_the_reward_peaked(tmp_path, tiny_overrides, monkeypatch):
    # the best_reward readout (beyond the paper): per trial, the pan of the image with the highest
    # reward −(eC + eF), the earliest on ties; the paper's q_p (pans) is the last pan.
    cfg = compose(tiny_overrides + ["env.initial_pan_jitter_deg=1"])
    trainer = Trainer(cfg, tmp_path)
    exp = trainer.exp
    physics = exp.envs[0].physics
    seen = []  # (position index, pan, reward) of every encoded image
    encode = type(exp.coder).encode

    def recording_encode(self, images, robots=slice(None)):
        encoding = encode(self, images, robots)
        if images.shape[0] == 1 and not torch.equal(images, self._last_reference):
            seen.append(
                (
                    round(physics.lateral_position(), 6),
                    physics.pan_deg(),
                    float(encoding.output.reward[0]),
                )
            )
        return encoding

    set_reference = type(exp.coder).set_reference

    def remembering_set_reference(self, reference):
        self._last_reference = torch.as_tensor(reference).clone()
        return set_reference(self, reference)

    monkeypatch.setattr(type(exp.coder), "encode", recording_encode)
    monkeypatch.setattr(type(exp.coder), "set_reference", remembering_set_reference)
    try:
        pres = exp.run_presentation(learn=False, greedy=False)
    finally:
        exp.close()
    for p, lateral in enumerate(pres.lateral_positions):
        trial = [(pan, reward) for l, pan, reward in seen if l == round(lateral, 6)]
        assert len(trial) == 4  # env.trial_length
        expected = max(trial, key=lambda pr: pr[1])[0]  # max() keeps the first on ties
        assert pres.read(BestReward)[0, p] == pytest.approx(expected, abs=1e-9)
        assert pres.pans[0, p] == pytest.approx(trial[-1][0], abs=1e-9)


def test_a_stop_signal_during_a_checkpoint_write_waits_for_the_rename(tmp_path):
    """SIGUSR2 (a scheduler's preemption) raised while the checkpoint is written is held back
    until the file is complete, then delivered."""
    import signal as sig

    from parallax import checkpoint

    seen = []
    old = sig.signal(sig.SIGUSR2, lambda *_: seen.append((tmp_path / "c.pt").exists()))
    try:

        class Raise:  # pickled by torch.save: raises the signal in the middle of the write
            def __reduce__(self):
                os.kill(os.getpid(), sig.SIGUSR2)
                return (dict, ())

        checkpoint.save_atomic({"a": list(range(1000)), "b": Raise()}, tmp_path / "c.pt")
    finally:
        sig.signal(sig.SIGUSR2, old)
    assert seen == [True]  # delivered once, after the rename
    assert checkpoint.load(tmp_path / "c.pt")["a"][-1] == 999


def test_resuming_with_other_settings_is_refused_and_loses_nothing(tmp_path, tiny_overrides):
    """Run directories are named by the overrides only: after a default changed in conf/, the
    same command must not continue an old run with the new value."""
    from parallax.config import changed_settings, load_run_config

    run = tmp_path / "run"
    overrides = tiny_overrides + ["train.presentations=1"]
    _train(run, overrides)
    saved = load_run_config(run)
    assert (
        changed_settings(saved, compose(overrides + ["train.presentations=5", "train.threads=2"]))
        == []
    )
    assert changed_settings(saved, compose(overrides + ["coder.learning_rate=0.3"])) == [
        "coder.learning_rate: 0.01 → 0.3"
    ]
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    cli = [
        sys.executable,
        "-m",
        "parallax.train",
        *overrides,
        "coder.learning_rate=0.3",
        f"hydra.run.dir={run}",
    ]
    proc = subprocess.run(cli, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if line.startswith("parallax-train: error")]
    assert len(errors) == 1 and "coder.learning_rate: 0.01 → 0.3" in errors[0]
    assert all(
        (run / name).read_bytes() == data for name, data in before.items()
    )  # Hydra may add train.log


def test_difference_states_change_the_run(tmp_path, tiny_overrides):
    # a short run's near-uniform policy may sample the same pans either way; what it learnt differs
    from parallax import checkpoint

    actors = []
    for norm in ("difference", "centred_unit"):
        _train(tmp_path / norm, tiny_overrides + [f"policy.feature_norm={norm}"])
        state = checkpoint.load(tmp_path / norm / "checkpoint.pt")["experiment"]["policy"]
        actors.append(state["actor"])
    assert actors[0].shape == actors[1].shape and not torch.equal(*actors)


def test_eye_position_feature_reaches_the_policy(tmp_path, tiny_overrides, monkeypatch):
    # policy.eye_position_reference_m > 0 (beyond the paper): the last state entry the policy acts
    # on is tan(pan)·d_ref/l for the pan of the image just encoded (the action is not applied yet).
    import math

    from parallax.policy import NaturalActorCritic

    # (the reward-change entry, on by default, would come after ν: off here)
    cfg = compose(
        tiny_overrides
        + [
            "policy.eye_position_reference_m=0.5",
            "env.initial_pan_jitter_deg=1",
            "policy.reward_change_gain=0",
        ]
    )
    trainer = Trainer(cfg, tmp_path)
    physics = trainer.exp.envs[0].physics
    seen, expected = [], []
    act = NaturalActorCritic.act

    def recording_act(self, phi, greedy=False):
        seen.append(float(phi[0, -1]))
        nearness = math.tan(math.radians(physics.pan_deg())) * 0.5 / physics.lateral_position()
        expected.append(max(-1.0, min(1.0, nearness)))
        return act(self, phi, greedy)

    monkeypatch.setattr(NaturalActorCritic, "act", recording_act)
    try:
        pres = trainer.exp.run_presentation()
    finally:
        trainer.exp.close()
    assert len(seen) == pres.steps - 1 and len(set(seen)) > 2
    assert seen == pytest.approx(expected, rel=1e-6, abs=1e-9)
    monkeypatch.undo()
    _train(
        tmp_path / "run",
        tiny_overrides + ["policy.eye_position_reference_m=0.5", "policy.reward_change_gain=0"],
    )
    from parallax import checkpoint

    actor = checkpoint.load(tmp_path / "run" / "checkpoint.pt")["experiment"]["policy"]["actor"]
    assert actor.shape[1] == 32 * 2 + 1 and bool(
        actor[:, -1].abs().sum() > 0
    )  # ν's weight was learnt


def test_reward_change_feature_reaches_the_policy(tmp_path, tiny_overrides, monkeypatch):
    # policy.reward_change_gain > 0 (beyond the paper): the last state entry is the reward's
    # relative change over the robot's last pan step, signed by the step; 0 at a trial's start.
    from parallax.policy import NaturalActorCritic

    cfg = compose(tiny_overrides + ["policy.reward_change_gain=10"])
    trainer = Trainer(cfg, tmp_path)
    physics = trainer.exp.envs[0].physics
    seen, pans = [], []
    act = NaturalActorCritic.act
    update = NaturalActorCritic.update
    rewards = []

    def recording_act(self, phi, greedy=False):
        seen.append(float(phi[0, -1]))
        pans.append(physics.pan_deg())
        return act(self, phi, greedy)

    def recording_update(self, phi, action, reward, next_phi, valid):
        rewards.append(float(reward[0]))
        return update(self, phi, action, reward, next_phi, valid)

    monkeypatch.setattr(NaturalActorCritic, "act", recording_act)
    monkeypatch.setattr(NaturalActorCritic, "update", recording_update)
    try:
        pres = trainer.exp.run_presentation()
    finally:
        trainer.exp.close()
    t_h = int(cfg.env.trial_length)
    assert len(seen) == pres.steps - 1 and any(abs(g) > 1e-3 for g in seen)
    # the first iteration of every trial has no previous step
    assert all(g == 0.0 for g in seen[::t_h])
    # within a trial: g = clip(10·Δr/|r_prev|·sign(Δpan)). Each trial makes t_h − 1 updates, the
    # k-th with the reward of its iteration k + 1 (the step into a trial's first image is not
    # learnt)
    trial_rewards = [rewards[i * (t_h - 1) : (i + 1) * (t_h - 1)] for i in range(len(seen) // t_h)]
    for i, rs in enumerate(trial_rewards):
        for k in range(1, len(rs)):
            step = pans[i * t_h + k + 1] - pans[i * t_h + k]
            sign = (step > 1e-9) - (step < -1e-9)
            expected = max(-1.0, min(1.0, 10 * (rs[k] - rs[k - 1]) / abs(rs[k - 1]) * sign))
            assert seen[i * t_h + k + 1] == pytest.approx(expected, rel=1e-4, abs=1e-6)
