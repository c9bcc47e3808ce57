"""One writer per run folder, and files that stay whole when that writer is killed.

:class:`RunLock` is the lock `parallax-train` and every tool that writes into a run folder
(parallax-eval, parallax-replay, the compaction, the soak) take before they write anything: the
file ``parallax.lock`` in the folder, locked with ``flock``. The kernel releases the lock when its
process ends, however it ends (SIGKILL, a node's power loss reported by the NFS lock manager), so
a lock left by a dead process is simply taken over: the file alone says nothing, only a lock
held on it. The file holds the holder's pid, host, start time and command, for the one line a
second process prints. On a file system that cannot lock files (NFS mounted with ``nolock``,
Lustre without ``flock``) the record itself is the lock: a holder on this host is checked by its
pid, one on another host is taken as alive until its file is removed.

:func:`write_atomic` writes a file through a temporary file in the same folder and a rename, so
that a kill leaves either the old file or the new one (summary.json, config.yaml, eval.json, the
trimmed metrics.jsonl); :func:`remove_leftovers` clears the temporary files a killed writer left.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import shlex
import socket
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

LOCK_NAME = "parallax.lock"

_HOST = socket.gethostname()
#: The folders whose locks this process holds. It never opens their lock files again: where
#: flock is emulated by POSIX locks (NFS), closing any descriptor of the file would release it.
_MINE: set[Path] = set()
#: the mode a plain open() would give a new file (mkstemp's is 0600)
_UMASK = os.umask(0)
os.umask(_UMASK)
#: flock's answers on a file system that cannot lock files at all
_NO_LOCKS = {errno.ENOLCK, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EINVAL}
#: how long a second process tries before it names the holder
_HOLDER_WAIT_S = 0.5


class RunLocked(RuntimeError):
    """The folder is being written by another process: ``<folder> is being written by …``. The
    commands add what to do."""

    def __init__(self, folder: Path, holder: str):
        super().__init__(f"{folder} is being written by {holder}")
        self.folder, self.holder = folder, holder


def _command(program: str | None) -> str:
    name = program or Path(sys.argv[0]).name
    return " ".join([name, shlex.join(sys.argv[1:])]).strip()


def _describe(record: dict | None, lock_path: Path, locks: bool) -> str:
    """The holder, in words, from its record."""
    if not record:
        return f"another process (its record in {lock_path} is not written yet)"
    since = record.get("since")
    when = f" since {since}" if since else ""
    text = (
        f"pid {record.get('pid')} on {record.get('host')}{when} "
        f"({record.get('command', 'command unknown')})"
    )
    if not locks:
        text += f"; this file system cannot lock files: if it has ended, remove {lock_path}"
    return text


def _read_record(path: Path) -> dict | None:
    try:
        text = path.read_text(encoding="utf-8").strip()
        record = json.loads(text) if text else None
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


def _own(record: dict | None) -> bool:
    return bool(record) and record.get("pid") == os.getpid() and record.get("host") == _HOST


def _alive_here(record: dict) -> bool:
    """Whether the holder of ``record`` may still run: on another host we cannot tell (yes)."""
    if record.get("host") != _HOST:
        return True
    try:
        os.kill(int(record["pid"]), 0)
    except (KeyError, TypeError, ValueError, ProcessLookupError):
        return False
    except PermissionError:  # another user's live process
        return True
    return True


class RunLock:
    """The lock on ``folder`` (created, with its parents, if missing) for this process; a context
    manager. :meth:`acquire` raises :class:`RunLocked` when another process holds it.
    ``program``: how the record names the command (default: the script's name)."""

    def __init__(self, folder: str | Path, program: str | None = None):
        self.folder = Path(folder).absolute()
        self.path = self.folder / LOCK_NAME
        self.program = program
        self.fd: int | None = None
        self.locks = True  # whether the file system locks files (else the record is the lock)
        self._created: list[Path] = []  # folders made for the lock, deepest last
        self._before: bytes | None = None  # a stale record found in the folder, if any

    # --- taking it -------------------------------------------------------------------------
    def acquire(self) -> RunLock:
        missing = []
        folder = self.folder
        while not folder.exists():
            missing.append(folder)
            folder = folder.parent
        self.folder.mkdir(parents=True, exist_ok=True)
        self._created = list(reversed(missing))
        try:
            while True:
                existed = self.path.exists()
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
                try:
                    held = self._lock(fd)
                except BaseException:
                    os.close(fd)
                    raise
                if held is not None:
                    os.close(fd)
                    raise RunLocked(self.folder, held)
                # the holder before us may have removed the file between our open and our lock:
                # then we hold a lock on a file that no longer names the folder's lock
                try:
                    same = os.path.samestat(os.fstat(fd), os.stat(self.path))
                except FileNotFoundError:
                    same = False
                if same:
                    break
                os.close(fd)
        except BaseException:
            self._remove_created()
            raise
        self.fd = fd
        self._before = os.pread(fd, 1 << 16, 0) if existed else None
        record = {
            "pid": os.getpid(),
            "host": _HOST,
            "since": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
            "command": _command(self.program),
        }
        data = (json.dumps(record) + "\n").encode("utf-8")
        os.ftruncate(fd, 0)
        os.pwrite(fd, data, 0)
        _MINE.add(self.folder)
        return self

    def _lock(self, fd: int) -> str | None:
        """Lock ``fd``; None when taken, else the holder in words."""
        # a moment's patience: another command may be looking at the lock (:func:`holder`
        # takes it shared for an instant), and a holder writes its record just after the lock
        deadline = time.monotonic() + _HOLDER_WAIT_S
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return None
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    return _describe(_read_record(self.path), self.path, locks=True)
                time.sleep(0.05)
            except OSError as exc:
                if exc.errno not in _NO_LOCKS:
                    raise
                self.locks = False
                record = _read_record(self.path)
                if record and not _own(record) and _alive_here(record):
                    return _describe(record, self.path, locks=False)
                return None

    # --- giving it back ------------------------------------------------------------------
    def release(self, restore: bool = False) -> None:
        """Give the lock back and remove its file; with ``restore`` (a command that refused to
        run), leave the folder as it was found: a stale record put back, folders made for the
        lock removed again."""
        if self.fd is None:
            return
        fd, self.fd = self.fd, None
        _MINE.discard(self.folder)
        try:
            if restore and self._before is not None:
                os.ftruncate(fd, 0)
                os.pwrite(fd, self._before, 0)
            else:
                # removed while still locked, so that no one locks the file on its way out
                self.path.unlink(missing_ok=True)
        finally:
            os.close(fd)
        if restore:
            self._remove_created()

    def _remove_created(self) -> None:
        for folder in reversed(self._created):
            with contextlib.suppress(OSError):
                folder.rmdir()
        self._created = []

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *error) -> None:
        self.release()


def holder(folder: str | Path) -> str | None:
    """Who holds ``folder``'s lock, in words, or None (none, or this process): asked without
    writing anything (the lock file, if there is one, is opened to read)."""
    if Path(folder).absolute() in _MINE:
        return None
    path = Path(folder).absolute() / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        record = _read_record(path)
        if _own(record):  # this process's own lock (flock sees another open file as another)
            return None
        return _describe(record, path, locks=True)
    except OSError as exc:
        if exc.errno not in _NO_LOCKS:
            return None
        record = _read_record(path)
        if record and not _own(record) and _alive_here(record):
            return _describe(record, path, locks=False)
        return None
    finally:
        os.close(fd)  # closing gives a shared lock taken here back
    return None


def write_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file beside it (``<name>.<random>.tmp``)
    and a rename: a kill at any moment leaves the old file or the new one, never half of one."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def remove_leftovers(folder: str | Path, names: Iterable[str]) -> list[Path]:
    """Remove the temporary files (:func:`write_atomic`'s and the checkpoints') that a writer
    killed mid-write left beside each of ``names`` in ``folder``; the files removed. Only the
    holder of the folder's lock may call it: no one else is writing."""
    removed = []
    folder = Path(folder)
    for name in names:
        for tmp in folder.glob(f"{name}.*.tmp"):
            tmp.unlink(missing_ok=True)
            removed.append(tmp)
    return removed


def probe_all(folders: Sequence[str | Path]) -> RunLocked | None:
    """The first of ``folders`` another process holds, as the error its lock would raise."""
    for folder in folders:
        held = holder(folder)
        if held is not None:
            return RunLocked(Path(folder).absolute(), held)
    return None
