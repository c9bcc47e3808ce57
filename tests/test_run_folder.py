"""One writer per run folder (parallax.run_folder): a second process on a folder another holds is
refused with one line naming the holder and writes nothing; a lock left by a killed process is
taken over; a write killed half way leaves the old file or the new one."""

from __future__ import annotations

import errno
import fcntl
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from parallax import run_folder
from parallax.run_folder import LOCK_NAME, RunLock, RunLocked, holder, write_atomic
from tests.conftest import TINY

#: A process that takes the lock of the folder argv[1] and waits (until it is killed).
HOLD = (
    "import sys, time\n"
    "from parallax.run_folder import RunLock\n"
    "RunLock(sys.argv[1], program='holder').acquire()\n"
    "print('held', flush=True)\n"
    "time.sleep(600)\n"
)


def _hold(folder: Path) -> subprocess.Popen:
    """Another process that holds ``folder``'s lock (until it is killed)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "held"
    return proc


@pytest.fixture
def held(tmp_path):
    """A folder whose lock another process holds: (folder, that process)."""
    folder = tmp_path / "run"
    proc = _hold(folder)
    try:
        yield folder, proc
    finally:
        proc.kill()
        proc.wait()


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _holder_words(pid: int) -> str:
    return f"pid {pid} on {socket.gethostname()} since "


def test_a_second_process_is_refused_and_a_killed_holder_is_taken_over(held):
    folder, proc = held
    before = _snapshot(folder)
    with pytest.raises(RunLocked) as error:
        RunLock(folder).acquire()
    line = str(error.value)
    assert line.startswith(f"{folder} is being written by {_holder_words(proc.pid)}"), line
    assert line.endswith(f" UTC (holder {folder})"), line
    assert holder(folder) == line.split(" is being written by ", 1)[1]
    assert _snapshot(folder) == before  # neither the refused lock nor the look wrote anything

    proc.kill()
    proc.wait()
    stale = (folder / LOCK_NAME).read_bytes()  # a SIGKILL leaves the file, not the lock
    assert json.loads(stale)["pid"] == proc.pid
    assert holder(folder) is None
    lock = RunLock(folder).acquire()
    assert json.loads((folder / LOCK_NAME).read_text())["pid"] == os.getpid()
    lock.release(restore=True)  # a command that refused: the stale record as it was
    assert (folder / LOCK_NAME).read_bytes() == stale
    with RunLock(folder):
        assert holder(folder) is None  # this process's own lock is no other's
    assert not (folder / LOCK_NAME).exists()


def test_a_refused_command_removes_the_folders_its_lock_made(tmp_path):
    lock = RunLock(tmp_path / "a" / "b").acquire()
    assert (tmp_path / "a" / "b" / LOCK_NAME).is_file()
    lock.release(restore=True)
    assert list(tmp_path.iterdir()) == []


@pytest.fixture
def no_file_locks(monkeypatch):
    """A file system that cannot lock files (NFS mounted with nolock, Lustre without flock)."""

    def flock(fd, operation):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", flock)


def test_without_file_locks_the_record_is_the_lock(tmp_path, no_file_locks):
    folder = tmp_path / "run"
    folder.mkdir()
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        text=True,
        capture_output=True,
        check=True,
    )
    record = {"pid": int(dead.stdout), "host": socket.gethostname(), "command": "gone"}
    (folder / LOCK_NAME).write_text(json.dumps(record))
    with RunLock(folder) as lock:  # its holder has ended: taken over
        assert not lock.locks
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        for host, pid in ((socket.gethostname(), alive.pid), ("elsewhere", 1)):
            (folder / LOCK_NAME).write_text(json.dumps({**record, "host": host, "pid": pid}))
            with pytest.raises(RunLocked) as error:
                RunLock(folder).acquire()
            assert str(error.value).endswith(
                f"(gone); this file system cannot lock files: if it has ended, remove "
                f"{folder / LOCK_NAME}"
            )
    finally:
        alive.kill()
        alive.wait()


def test_an_atomic_write_that_fails_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "summary.json"
    write_atomic(path, "old\n")
    assert path.stat().st_mode & 0o777 == 0o666 & ~run_folder._UMASK

    def fail(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", fail)
    with pytest.raises(OSError):
        write_atomic(path, "new\n")
    assert path.read_text() == "old\n" and sorted(tmp_path.iterdir()) == [path]


# --- the tools -------------------------------------------------------------------------------
@pytest.fixture
def finished(tmp_path) -> Path:
    """A folder the tools take for a finished run (its config and summary; no checkpoint)."""
    from omegaconf import OmegaConf

    from parallax.config import compose

    run = tmp_path / "finished"
    run.mkdir()
    (run / "config.yaml").write_text(OmegaConf.to_yaml(compose(TINY), resolve=True))
    (run / "summary.json").write_text("{}\n")
    (run / "metrics.jsonl").write_text("")
    return run


def _refused(capsys, exit_, prefix: str, folder: Path, pid: int) -> str:
    assert exit_.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(
        f"{prefix} {folder} is being written by {_holder_words(pid)}"
    ), lines
    return lines[0]


def test_the_tools_refuse_a_folder_another_process_writes(finished, tmp_path, capsys):
    from parallax.tools.evaluate import main as evaluate
    from parallax.tools.replay import main as replay
    from parallax.tools.report.compact import main as compact

    target = tmp_path / "replayed" / finished.name / "default"
    holders = [_hold(finished), _hold(target)]
    try:
        before = _snapshot(tmp_path)
        with pytest.raises(SystemExit) as exit_:
            evaluate([str(finished), "--distances", "4.0", "--between", "--greedy-only"])
        line = _refused(capsys, exit_, "parallax-eval: error:", finished, holders[0].pid)
        assert line.endswith("; wait for it to end, or write elsewhere with --out DIR")
        with pytest.raises(SystemExit) as exit_:
            replay([str(finished), "--out", str(tmp_path / "replayed")])
        line = _refused(capsys, exit_, "parallax-replay: error:", target, holders[1].pid)
        assert line.endswith("; wait for it to end, or choose another --out")
        with pytest.raises(SystemExit) as exit_:
            compact([str(finished)])
        line = _refused(capsys, exit_, "[compact] error:", finished, holders[0].pid)
        assert line.endswith("; wait for it to end")
        assert _snapshot(tmp_path) == before
    finally:
        for proc in holders:
            proc.kill()
            proc.wait()


# --- parallax-train ----------------------------------------------------------------------------
def _train_command(run: Path, overrides: list[str]) -> list[str]:
    return [sys.executable, "-m", "parallax.train", *overrides, f"hydra.run.dir={run}"]


def test_parallax_train_on_a_folder_in_use_writes_nothing(held, tmp_path):
    folder, proc = held
    before = _snapshot(folder)
    refused = subprocess.run(
        _train_command(folder, TINY), capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    assert refused.returncode == 2, refused.stderr
    lines = [line for line in refused.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, refused.stderr
    assert lines[0].startswith(
        f"parallax-train: error: {folder} is being written by {_holder_words(proc.pid)}"
    )
    assert lines[0].endswith(
        f"(holder {folder}); wait for it to end, or choose another folder with hydra.run.dir=..."
    )
    assert _snapshot(folder) == before


def test_a_sweep_with_a_job_folder_in_use_is_refused_before_its_first_job(held):
    from parallax.train import check_command_line

    folder, proc = held
    sweep = ["-m", *TINY, "seed=0", f"hydra.sweep.dir={folder.parent}", "hydra.sweep.subdir=run"]
    line = check_command_line(sweep)
    assert line is not None and line.startswith(
        f"{folder} is being written by {_holder_words(proc.pid)}"
    )
    assert line.endswith("choose another folder with hydra.sweep.dir=...")


@pytest.mark.slow
def test_two_parallax_train_processes_on_one_folder(tmp_path):
    """The issue as a user met it: the same command started twice on one folder. The second is
    refused with one line naming the first; the first runs to the end, its record in order."""
    run = tmp_path / "run"
    overrides = [*TINY, "train.presentations=3", "train.checkpoint_every=1"]
    first = subprocess.Popen(
        _train_command(run, overrides),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    deadline = time.time() + 300
    while time.time() < deadline and first.poll() is None and holder(run) is None:
        time.sleep(0.05)
    assert first.poll() is None, "the first run ended before the second started"
    second = subprocess.run(
        _train_command(run, overrides), capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    first_err = first.communicate(timeout=600)[1]
    assert first.returncode == 0, first_err
    assert second.returncode == 2, second.stderr
    lines = [line for line in second.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(
        f"parallax-train: error: {run} is being written by {_holder_words(first.pid)}"
    ), second.stderr
    assert "hydra.run.dir=" in lines[0] and "train.presentations=3" in lines[0]
    records = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["presentation"] for r in records] == [1, 2, 3]
    assert not (run / LOCK_NAME).exists()


# --- a kill in the middle of a write ---------------------------------------------------------
#: parallax-train (argv[3:]) killed by SIGKILL in the middle of a write: "metrics" half way
#: through presentation argv[2]'s line of metrics.jsonl, "summary" when summary.json's
#: temporary file is written but not yet renamed into place.
KILL_IN_A_WRITE = """
import json, os, signal, sys
from parallax import run_log, train

what, at = sys.argv[1], int(sys.argv[2])
if what == "metrics":
    write = run_log.RunLog.write

    def killed_in_the_line(self, record, rate):
        if record.presentation == at:
            line = json.dumps(record.to_json()) + "\\n"
            self.metrics.write(line[: len(line) // 2])
            self.metrics.flush()
            os.kill(os.getpid(), signal.SIGKILL)
        return write(self, record, rate)

    run_log.RunLog.write = killed_in_the_line
else:
    fsync = os.fsync

    def killed_before_the_rename(fd):
        fsync(fd)
        if os.path.basename(os.readlink(f"/proc/self/fd/{fd}")).startswith("summary.json."):
            os.kill(os.getpid(), signal.SIGKILL)

    os.fsync = killed_before_the_rename
sys.argv = ["parallax-train", *sys.argv[3:]]
train.main()
"""


def _without_timing(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k != "timing"}


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs Linux's /proc")
def test_a_kill_in_the_middle_of_a_write_loses_nothing(tmp_path):
    """metrics.jsonl torn in a line and summary.json killed before its rename: each resume
    repairs the folder, and the run ends with the uninterrupted run's numbers."""
    from tests.conftest import train_tiny_run

    overrides = [*TINY, "train.presentations=4", "train.checkpoint_every=1"]
    reference = train_tiny_run(tmp_path / "reference", overrides[len(TINY) :])
    run = tmp_path / "run"
    command = [*overrides, f"hydra.run.dir={run}"]

    def killed(what: str, at: int) -> None:
        proc = subprocess.run(
            [sys.executable, "-c", KILL_IN_A_WRITE, what, str(at), *command],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            timeout=600,
        )
        assert proc.returncode == -signal.SIGKILL, proc.stderr
        assert json.loads((run / LOCK_NAME).read_text())["pid"]  # stale: left by the kill

    killed("metrics", 3)
    text = (run / "metrics.jsonl").read_text()
    assert not text.endswith("\n")  # the torn line
    assert [json.loads(line)["presentation"] for line in text.splitlines()[:-1]] == [1, 2]
    killed("summary", 0)
    assert not (run / "summary.json").exists() and list(run.glob("summary.json.*.tmp"))
    subprocess.run(
        _train_command(run, overrides), check=True, capture_output=True, cwd=tmp_path, timeout=600
    )
    assert (run / "metrics.jsonl").read_text() == (reference / "metrics.jsonl").read_text()
    a, b = (json.loads((d / "summary.json").read_text()) for d in (reference, run))
    assert _without_timing(a) == _without_timing(b)
    assert not list(run.glob("*.tmp")) and not (run / LOCK_NAME).exists()
    # TensorBoard reads the torn event files; every point it shows is the uninterrupted run's
    read, expected = _read_tensorboard(run), _read_tensorboard(reference)
    assert read["pursuit/mae"] and set(read["pursuit/mae"]) <= set(expected["pursuit/mae"])


def _read_tensorboard(run: Path) -> dict[str, list[float]]:
    """pursuit/mae as TensorBoard reads it from the run's event files, torn ones included."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run / "tb"))
    events.Reload()  # a torn last event is skipped, not an error
    tags = events.Tags()["scalars"]
    return {tag: [s.value for s in events.Scalars(tag)] for tag in tags if tag == "pursuit/mae"}


@pytest.mark.slow
def test_kills_at_random_moments_leave_whole_records(tmp_path):
    """SIGKILL at random moments, each followed by a resume: after every kill each record is
    whole (but a torn last line of metrics.jsonl), and the run ends as the uninterrupted one."""
    import random

    from parallax import checkpoint
    from tests.conftest import train_tiny_run

    overrides = [*TINY, "train.presentations=6", "train.checkpoint_every=1"]
    reference = train_tiny_run(tmp_path / "reference", overrides[len(TINY) :])
    run = tmp_path / "run"
    draw = random.Random()
    seed = draw.randrange(1 << 30)
    draw.seed(seed)
    for _ in range(3):
        proc = subprocess.Popen(
            _train_command(run, overrides),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            cwd=tmp_path,
        )
        time.sleep(draw.uniform(5.0, 40.0))
        proc.kill()
        proc.wait()
        if not run.is_dir():
            continue
        metrics = run / "metrics.jsonl"
        lines = metrics.read_text().splitlines() if metrics.exists() else []
        for line in lines[:-1]:
            json.loads(line)  # only the last line may be torn
        for name in ("summary.json", "config.yaml"):
            if (run / name).exists():
                assert (run / name).read_text().endswith("\n"), f"seed {seed}: {name}"
        for name in (checkpoint.CHECKPOINT_NAME, checkpoint.PREVIOUS_NAME):
            if (run / name).exists():
                checkpoint.read(run / name)
        if (run / "tb").is_dir():
            _read_tensorboard(run)  # a torn last event is no error
    subprocess.run(
        _train_command(run, overrides), check=True, capture_output=True, cwd=tmp_path, timeout=900
    )
    assert (run / "metrics.jsonl").read_text() == (reference / "metrics.jsonl").read_text(), (
        f"seed {seed}"
    )
    a, b = (json.loads((d / "summary.json").read_text()) for d in (reference, run))
    assert _without_timing(a) == _without_timing(b), f"seed {seed}"
