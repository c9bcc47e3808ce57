"""What a long command tells its user: a header (what it does, on what), progress with an estimate
of the time left, and where its output went.

Everything goes to stderr, so that a tool's results on stdout can still be piped. On a terminal
the progress is a tqdm bar; elsewhere (a log file, a pipe) tqdm's updates become whole lines, a
few a minute, instead of carriage returns.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO

from tqdm import tqdm

#: The files a footer names before it counts the rest.
SHOWN = 8


class _Lines:
    """A stream for tqdm off a terminal: each redraw as a line of its own."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def write(self, text: str) -> None:
        text = text.replace("\r", "").rstrip()
        if text:
            self.stream.write(text + "\n")

    def flush(self) -> None:
        self.stream.flush()


def header(tool: str, what: str, **details: Any) -> None:
    """``[tool] what`` and one ``[tool]   key: value`` line per detail (None left out)."""
    lines = [f"[{tool}] {what}"]
    lines += [
        f"[{tool}]   {key.replace('_', ' ')}: {v}" for key, v in details.items() if v is not None
    ]
    print("\n".join(lines), file=sys.stderr, flush=True)


def progress(iterable: Iterable | None = None, total: int | None = None, desc: str = "", **kw):
    """A tqdm bar on stderr with the time left (``with progress(total=n) as bar: bar.update()``,
    or ``for x in progress(items)``)."""
    interactive = sys.stderr.isatty()
    return tqdm(
        iterable,
        total=total,
        desc=desc,
        file=sys.stderr if interactive else _Lines(sys.stderr),
        dynamic_ncols=interactive,
        mininterval=0.5 if interactive else 15.0,
        # off a terminal, a step that ends within seconds leaves no line behind
        delay=0.0 if interactive else 5.0,
        **kw,
    )


def footer(tool: str, paths: Iterable[str | Path], folder: str | Path | None = None) -> None:
    """``[tool] wrote A, B to FOLDER`` (absolute; paths relative to it), or ``[tool] wrote
    PATH`` per file."""
    paths = [Path(p) for p in paths]
    if not paths:
        return
    if folder is not None:
        names = [p.name if p.is_absolute() else str(p) for p in paths]
        more = f" and {len(names) - SHOWN} more" if len(names) > SHOWN else ""
        line = f"[{tool}] wrote {', '.join(names[:SHOWN])}{more} to {Path(folder).resolve()}"
    else:
        line = "\n".join(f"[{tool}] wrote {p.resolve()}" for p in paths)
    print(line, file=sys.stderr, flush=True)
