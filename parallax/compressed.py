"""A run's record files (metrics.jsonl, eval.json) kept plain or compressed (``.xz``, ``.gz``):
the committed runs are compressed (``python -m parallax.tools.report.compact``), and the trainer,
resuming one, and every reader take either form by the record's plain name."""

from __future__ import annotations

import gzip
import lzma
from pathlib import Path

#: The compressed forms of a record a reader takes, by suffix, in the order they are looked for.
COMPRESSED = {".xz": lzma.open, ".gz": gzip.open}


def record_forms(path: Path | str) -> list[Path]:
    """Every file that may hold the record ``path``: the plain file, then its compressed forms."""
    path = Path(path)
    return [path.with_name(path.name + suffix) for suffix in ("", *COMPRESSED)]


def record_file(path: Path | str) -> Path | None:
    """The file that holds the record ``path`` (say RUN/metrics.jsonl): the plain file, else its
    compressed form (``metrics.jsonl.xz`` or ``.gz``), else None. The plain file wins: the tools
    write plain files, so one beside a compressed copy is the newer record."""
    return next((form for form in record_forms(path) if form.is_file()), None)


def read_record(path: Path | str) -> str:
    """The text of the record ``path``, plain or compressed (:func:`record_file`); a
    FileNotFoundError naming ``path`` when there is neither."""
    found = record_file(path)
    if found is None:
        raise FileNotFoundError(f"{path}: no such file, plain or compressed")
    opener = COMPRESSED.get(found.suffix)
    if opener is None:
        return found.read_text()
    with opener(found, "rt", encoding="utf-8") as handle:
        return handle.read()
