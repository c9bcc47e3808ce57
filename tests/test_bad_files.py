"""Bad files and bad places: a checkpoint that cannot be used and an output folder that cannot be
written end each command with one line naming the file or folder and what to do, exit status 2,
and nothing written or changed; a run whose latest checkpoint was damaged resumes from the one
before it to the numbers of an uninterrupted run."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from parallax import checkpoint
from parallax.train import check_command_line
from tests.conftest import TINY

#: The finished tiny run the tests damage copies of: three presentations, a checkpoint after each.
RUN_OVERRIDES = [*TINY, "train.presentations=3", "train.checkpoint_every=1"]


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    from tests.conftest import train_tiny_run

    run = train_tiny_run(tmp_path_factory.mktemp("finished") / "run", RUN_OVERRIDES[len(TINY) :])
    assert (run / checkpoint.CHECKPOINT_NAME).is_file()
    assert (run / checkpoint.PREVIOUS_NAME).is_file()
    return run


@pytest.fixture
def run(finished_run, tmp_path) -> Path:
    """A copy of the finished run, for a test to damage."""
    return Path(shutil.copytree(finished_run, tmp_path / "run"))


def _replace(path: Path, data: bytes) -> None:
    """Write ``data`` as a new file at ``path`` (a damaged copy, as a full disk leaves one)."""
    tmp = path.with_name(path.name + ".new")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _other_settings(state: dict) -> dict:
    state["config"]["coder"]["atoms"] = 16
    return state


def _without_eye(state: dict) -> dict:
    del state["eye"]
    return state


def _nan_policy(state: dict) -> dict:
    """The policy's tensors overwritten with NaN: a file that loads and has every part."""
    for value in state["experiment"]["policy"].values():
        if isinstance(value, torch.Tensor) and value.is_floating_point():
            value.fill_(float("nan"))
    return state


#: name → (how the checkpoint is damaged, what the line says about it)
DAMAGES = {
    "truncated": (lambda data, state: data[:3000], "is truncated or damaged (3000 bytes;"),
    "empty": (lambda data, state: b"", "is empty"),
    "text": (lambda data, state: b"not a checkpoint\n" * 10, "is not a torch checkpoint"),
    "list": (lambda data, state: [1, 2, 3], "is not a checkpoint of parallax-train"),
    "missing_key": (lambda data, state: _without_eye(state), "lacks eye"),
    "other_run": (
        lambda data, state: _other_settings(state),
        "was written by a run with other settings (coder.atoms: 16 → 32)",
    ),
    "nan": (
        lambda data, state: _nan_policy(state),
        "holds numbers that are not finite (experiment.policy.",
    ),
}


def _damage(path: Path, kind: str) -> None:
    make, _ = DAMAGES[kind]
    damaged = make(path.read_bytes(), checkpoint.load(path))
    if isinstance(damaged, bytes):
        _replace(path, damaged)
    else:
        checkpoint.save_atomic(damaged, path)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _one_line(stderr: str, prefix: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith(prefix), lines[0]
    return lines[0]


def _parallax_train(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "parallax.train", *args]
    return subprocess.run(command, capture_output=True, text=True, cwd=cwd, timeout=300)


# --- checkpoints -----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", sorted(DAMAGES))
def test_a_damaged_checkpoint_stops_a_resume_with_one_line(run, kind):
    _damage(run / checkpoint.CHECKPOINT_NAME, kind)
    before = _snapshot(run)
    line = check_command_line([*RUN_OVERRIDES, f"hydra.run.dir={run}"])
    assert line is not None and "\n" not in line
    assert line.startswith(f"{run / checkpoint.CHECKPOINT_NAME} {DAMAGES[kind][1]}"), line
    assert line.endswith(
        "resume from the one before with train.resume_from=previous, or move the checkpoints "
        "aside to start afresh"
    )
    assert _snapshot(run) == before


def test_parallax_train_leaves_the_folder_of_a_damaged_checkpoint_as_it_was(run, tmp_path):
    """Hydra's own record (.hydra/) included: the checkpoint is checked before Hydra starts."""
    _damage(run / checkpoint.CHECKPOINT_NAME, "truncated")
    before = _snapshot(run)
    proc = _parallax_train([*RUN_OVERRIDES, f"hydra.run.dir={run}"], tmp_path)
    assert proc.returncode == 2, proc.stderr
    _one_line(proc.stderr, f"parallax-train: error: {run / checkpoint.CHECKPOINT_NAME} is trunc")
    assert "Traceback" not in proc.stderr + proc.stdout
    assert _snapshot(run) == before


def _no_config(state: dict) -> dict:
    """Another version's checkpoint: no settings recorded, and a part the models lack."""
    del state["config"], state["experiment"]["policy"]
    return state


#: Every reason a resume is refused: name → (what is done to the run, extra overrides, the
#: start of the line after "parallax-train: error: " with RUN for the run's folder)
REFUSALS = {
    "truncated": ("truncated", [], "RUN/checkpoint.pt is truncated or damaged (3000 bytes;"),
    "foreign": ("text", [], "RUN/checkpoint.pt is not a torch checkpoint"),
    "other_run": ("other_run", [], "RUN/checkpoint.pt was written by a run with other settings"),
    "non_finite": ("nan", [], "RUN/checkpoint.pt holds numbers that are not finite (experiment."),
    "not_fitting": (
        _no_config,
        [],
        "RUN/checkpoint.pt does not fit this run's models (KeyError: 'policy')",
    ),
    "changed_config": (
        None,
        ["coder.learning_rate=0.3"],
        "resume=true: cannot resume RUN, it was trained with other settings "
        "(coder.learning_rate: 0.01 → 0.3)",
    ),
}


@pytest.mark.parametrize("reason", sorted(REFUSALS))
def test_every_refused_resume_leaves_the_folder_byte_for_byte(run, reason, monkeypatch, capsys):
    """parallax-train's own entry point, on the folder of a run that cannot be resumed: one line,
    exit status 2, and not a byte of the folder changed (Hydra's .hydra/ included)."""
    from parallax import train

    damage, extra, expected = REFUSALS[reason]
    if isinstance(damage, str):
        _damage(run / checkpoint.CHECKPOINT_NAME, damage)
    elif damage is not None:
        state = damage(checkpoint.load(run / checkpoint.CHECKPOINT_NAME))
        checkpoint.save_atomic(state, run / checkpoint.CHECKPOINT_NAME)
    before = _snapshot(run)
    monkeypatch.setattr(
        sys,
        "argv",
        ["parallax-train", *RUN_OVERRIDES, *extra, "train.presentations=4", f"hydra.run.dir={run}"],
    )
    with pytest.raises(SystemExit) as exit_:
        train.main()
    assert exit_.value.code == 2
    line = _one_line(capsys.readouterr().err, "parallax-train: error: ")
    assert line.startswith("parallax-train: error: " + expected.replace("RUN", str(run))), line
    assert _snapshot(run) == before
    assert train._held is None and train._prepared is None


def test_a_checkpoint_of_a_study_of_divergence_may_hold_numbers_that_are_not_finite(run):
    _damage(run / checkpoint.CHECKPOINT_NAME, "nan")
    command = [*RUN_OVERRIDES, f"hydra.run.dir={run}"]
    assert "not finite" in check_command_line(command)
    assert check_command_line([*command, "train.stop_after_non_finite=null"]) is None


def test_resume_from_previous_needs_a_previous_checkpoint(run):
    (run / checkpoint.PREVIOUS_NAME).unlink()
    line = check_command_line(
        [*RUN_OVERRIDES, "train.resume_from=previous", f"hydra.run.dir={run}"]
    )
    assert line == (
        f"train.resume_from=previous: {run} has no {checkpoint.PREVIOUS_NAME} to resume from"
    )


def test_a_previous_checkpoint_without_the_latest_is_not_trained_over(run):
    (run / checkpoint.CHECKPOINT_NAME).unlink()
    line = check_command_line([*RUN_OVERRIDES, f"hydra.run.dir={run}"])
    assert line is not None and line.startswith(
        f"{run} holds {checkpoint.PREVIOUS_NAME} but no {checkpoint.CHECKPOINT_NAME}; resume "
        "from it with train.resume_from=previous"
    )


def test_a_checkpoint_whose_parts_do_not_fit_is_named_when_restored(run):
    """A checkpoint that records no settings (another version's) and whose parts do not fit the
    run's models is caught where it is loaded."""
    from parallax.config import compose
    from parallax.trainer import Trainer

    state = checkpoint.load(run / checkpoint.CHECKPOINT_NAME)
    del state["config"], state["experiment"]["policy"]
    checkpoint.save_atomic(state, run / checkpoint.CHECKPOINT_NAME)
    trainer = Trainer(compose(RUN_OVERRIDES), run)
    try:
        with pytest.raises(checkpoint.CheckpointError) as error:
            trainer.restore()
    finally:
        trainer.exp.close()
    assert str(error.value) == (
        f"{run / checkpoint.CHECKPOINT_NAME} does not fit this run's models (KeyError: 'policy')"
    )


@pytest.mark.parametrize("kind", ["truncated", "missing_key", "other_run", "nan"])
def test_parallax_eval_names_a_damaged_checkpoint(run, kind, capsys):
    from parallax.tools.evaluate import main

    _damage(run / checkpoint.CHECKPOINT_NAME, kind)
    before = _snapshot(run)
    with pytest.raises(SystemExit) as exit_:
        main([str(run), "--distances", "4.0", "--between", "--greedy-only"])
    assert exit_.value.code == 2
    line = _one_line(
        capsys.readouterr().err,
        f"parallax-eval: error: {run / checkpoint.CHECKPOINT_NAME} {DAMAGES[kind][1]}",
    )
    assert line.endswith(f"evaluate the one before with --checkpoint {checkpoint.PREVIOUS_NAME}")
    assert _snapshot(run) == before


@pytest.mark.parametrize("kind", ["text", "nan"])
def test_parallax_replay_names_a_damaged_checkpoint_and_writes_nothing(run, tmp_path, capsys, kind):
    from parallax.tools.replay import main

    _damage(run / checkpoint.CHECKPOINT_NAME, kind)
    with pytest.raises(SystemExit) as exit_:
        main([str(run), "--out", str(tmp_path / "replayed")])
    assert exit_.value.code == 2
    line = _one_line(
        capsys.readouterr().err,
        f"parallax-replay: error: {run / checkpoint.CHECKPOINT_NAME} "
        + {"text": "is not a torch checkpoint", "nan": DAMAGES["nan"][1]}[kind],
    )
    assert line.endswith("move it aside to replay without it")
    assert not (tmp_path / "replayed").exists()


def test_each_save_keeps_the_checkpoint_before(tmp_path):
    path, previous = tmp_path / "c.pt", tmp_path / "p.pt"
    for n in range(3):
        checkpoint.save_atomic({"n": n}, path, previous=previous)
    assert checkpoint.load(path) == {"n": 2} and checkpoint.load(previous) == {"n": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.pt", "p.pt"]  # no temporary left


def test_a_run_whose_last_checkpoint_is_damaged_resumes_from_the_one_before(tmp_path):
    """Killed mid-run, its latest checkpoint damaged: the same command refuses with one line and
    changes nothing (parallax-train's own exit is tested above); with train.resume_from=previous
    it ends with the uninterrupted run's numbers."""
    from tests.conftest import train_tiny_run

    overrides = [*TINY, "train.presentations=6", "train.checkpoint_every=1"]
    reference = train_tiny_run(tmp_path / "reference", overrides[len(TINY) :])
    killed = tmp_path / "killed"
    command = [sys.executable, "-m", "parallax.train", *overrides, f"hydra.run.dir={killed}"]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    metrics = killed / "metrics.jsonl"
    while time.time() < deadline and proc.poll() is None:
        if metrics.exists() and len(metrics.read_text().splitlines()) >= 3:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be killed; make it longer"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    latest = killed / checkpoint.CHECKPOINT_NAME
    written = checkpoint.load(latest)["presentation"]
    assert checkpoint.load(killed / checkpoint.PREVIOUS_NAME)["presentation"] == written - 1
    _replace(latest, latest.read_bytes()[:3000])
    before = _snapshot(killed)

    refused = check_command_line([*overrides, f"hydra.run.dir={killed}"])
    assert refused is not None and refused.startswith(f"{latest} is truncated or damaged")
    assert _snapshot(killed) == before

    resumed = [*overrides, "train.resume_from=previous", f"hydra.run.dir={killed}"]
    assert check_command_line(resumed) is None
    train_tiny_run(killed, [*overrides[len(TINY) :], "train.resume_from=previous"])
    assert (killed / "metrics.jsonl").read_text() == (reference / "metrics.jsonl").read_text()
    a, b = (json.loads((d / "summary.json").read_text()) for d in (reference, killed))
    assert {k: v for k, v in a.items() if k != "timing"} == {
        k: v for k, v in b.items() if k != "timing"
    }
    # the damaged checkpoint was written over, never kept as the previous one
    assert checkpoint.read(killed / checkpoint.PREVIOUS_NAME)["presentation"] == 5
    assert checkpoint.read(latest)["presentation"] == 6


# --- output folders --------------------------------------------------------------------------
@pytest.fixture
def blocked(tmp_path) -> Path:
    """A folder that cannot be created: its parent is a file."""
    (tmp_path / "a_file").write_text("")
    return tmp_path / "a_file" / "out"


def test_parallax_train_names_an_output_folder_it_cannot_create(blocked, tmp_path):
    line = check_command_line([*TINY, f"hydra.run.dir={blocked}"])
    assert line == (
        f"hydra.run.dir={blocked}: lies inside {blocked.parent}, a file; choose another folder "
        "with hydra.run.dir=..."
    )
    line = check_command_line(["-m", "seed=0,1", f"hydra.sweep.dir={blocked}"])
    assert line is not None and line.startswith(f"hydra.sweep.dir={blocked}/seed=0: lies inside")


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_parallax_train_under_proc_is_one_line_and_exit_2(tmp_path):
    proc = _parallax_train(["hydra.run.dir=/proc/x"], tmp_path)
    assert proc.returncode == 2, proc.stderr
    _one_line(proc.stderr, "parallax-train: error: hydra.run.dir=/proc/x: cannot be created (")
    assert "Traceback" not in proc.stderr and list(tmp_path.iterdir()) == []


def test_the_tools_name_an_output_folder_they_cannot_write(finished_run, blocked, capsys):
    from parallax.tools.bench import cli as bench
    from parallax.tools.evaluate import main as evaluate
    from parallax.tools.replay import main as replay
    from parallax.tools.report.cli import main as report

    before = _snapshot(finished_run)
    calls = {
        "parallax-eval": lambda: evaluate([str(finished_run), "--out", str(blocked)]),
        "parallax-replay": lambda: replay([str(finished_run), "--out", str(blocked)]),
        "parallax-report": lambda: report([str(finished_run), "--out", str(blocked)]),
        "parallax-bench": lambda: bench.main(["--json", str(blocked / "bench.json")]),
    }
    for program, call in calls.items():
        with pytest.raises(SystemExit) as exit_:
            call()
        assert exit_.value.code == 2, program
        flag = "--json" if program == "parallax-bench" else "--out"
        _one_line(capsys.readouterr().err, f"{program}: error: {flag} {blocked}")
    assert not blocked.parent.is_dir() and _snapshot(finished_run) == before
