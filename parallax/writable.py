"""Whether a command can write where it was told to: checked before it writes anything, so that
an output folder that cannot be created or written ends the command with one line instead of a
traceback after part of the work (parallax-train, parallax-eval --out, parallax-replay --out,
parallax-report --out, parallax-bench --json).

The answer comes from trying: a temporary folder or file is made in the nearest folder that
exists and removed at once, since permission bits do not tell (root may write anywhere but
/proc, a read-only mount refuses everyone).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and not path.is_symlink() and path != path.parent:
        path = path.parent
    return path


def folder_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot be made (or is not) a folder to write into, or None if it can."""
    path = Path(path).absolute()
    existing = _nearest_existing(path)
    if not existing.is_dir():
        what = "is not a folder" if existing == path else f"lies inside {existing}, a file"
        return what if existing.exists() else f"lies below {existing}, a broken link"
    try:
        if existing == path:
            fd, probe = tempfile.mkstemp(prefix=".parallax-write-test-", dir=path)
            os.close(fd)
            os.unlink(probe)
        else:
            os.rmdir(tempfile.mkdtemp(prefix=".parallax-write-test-", dir=existing))
    except OSError as exc:
        reason = exc.strerror or str(exc)
        if existing == path:
            return f"cannot be written into ({reason})"
        return f"cannot be created ({existing} refuses new folders: {reason})"
    return None


def file_problem(path: str | Path) -> str | None:
    """Why a file cannot be written at ``path``, or None: its folder must be one to write into
    and the file, if it exists, a file that can be opened for writing."""
    path = Path(path).absolute()
    if path.is_dir():
        return "is a folder"
    problem = folder_problem(path.parent)
    if problem:
        return f"cannot be written: its folder {path.parent} {problem}"
    if path.exists():
        try:
            with path.open("ab"):  # appends nothing: the file is left as it is
                pass
        except OSError as exc:
            return f"cannot be written ({exc.strerror or exc})"
    return None
