"""Compacts finished runs' records for committing: each `metrics.jsonl` and `eval.json` becomes
`metrics.jsonl.xz` / `eval.json.xz`, which every reader of the report, replay and analysis tools
takes in place of the plain file (`parallax.tools.report.runs.read_record`).

    python -m parallax.tools.report.compact RUN_OR_MULTIRUN_DIR…   # what reproduce.sh runs
    python -m parallax.tools.report.compact … --format gz          # gzip instead of xz

Only finished runs are compacted (a `summary.json` beside the `config.yaml`): the trainer resumes
an unfinished run from its plain `metrics.jsonl`. In each, the run's `metrics.jsonl` and the
`eval.json` of the run and of the folders one level below it (`parallax-eval --out RUN/SUBDIR`).
A plain file is removed only once its compressed copy reads back the same text; the copy keeps
the plain file's modification time, so that "is the checkpoint newer than its eval" reads as
before. The output is deterministic (xz has no time stamp; gzip's is 0 and it names no file): the
same record always compresses to the same bytes. A record already compressed in the other format
is converted; figures and everything else are left alone (docs/results/runs/.gitignore keeps the
runs' figures out of git).
"""

from __future__ import annotations

import argparse
import gzip
import lzma
import os
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

from parallax.tools.report.runs import (
    COMPRESSED,
    METRICS_NAME,
    SUMMARY_NAME,
    ReportError,
    eval_files,
    find_run_dirs,
    read_record,
    record_file,
)

FORMATS = {"xz": ".xz", "gz": ".gz"}


def compress(data: bytes, suffix: str) -> bytes:
    """``data`` compressed the way ``suffix`` (.xz or .gz) names, deterministically."""
    if suffix == ".xz":
        return lzma.compress(data, format=lzma.FORMAT_XZ)  # preset 6: 9 gains nothing here
    if suffix == ".gz":
        return gzip.compress(data, compresslevel=9, mtime=0)
    raise ValueError(f"no compressed format {suffix!r}; one of {', '.join(COMPRESSED)}")


def compact_record(path: Path, suffix: str = ".xz") -> Path | None:
    """The record ``path`` (its plain name) compressed as ``path`` + ``suffix``; the plain file
    and any other compressed form removed. None when there is no such record."""
    found = record_file(path)
    if found is None:
        return None
    target = path.with_name(path.name + suffix)
    if found == target:
        return target
    text = read_record(path)
    packed = compress(text.encode("utf-8"), suffix)
    partial = target.with_name(target.name + ".tmp")
    partial.write_bytes(packed)
    if _unpack(partial, suffix) != text:
        partial.unlink()
        raise OSError(f"{partial} does not read back as {found}; left {found} as it was")
    stat = found.stat()
    os.utime(partial, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    partial.replace(target)
    for other in ("", *COMPRESSED):
        stale = path.with_name(path.name + other)
        if other != suffix and stale.is_file():
            stale.unlink()
    return target


def _unpack(path: Path, suffix: str) -> str:
    with COMPRESSED[suffix](path, "rt", encoding="utf-8") as handle:
        return handle.read()


def run_records(run: Path) -> list[Path]:
    """The records of a finished run that compaction keeps compressed, by their plain names."""
    records = [run / METRICS_NAME] if record_file(run / METRICS_NAME) is not None else []
    return records + eval_files(run)


def finished_runs(paths: Iterable[str | Path]) -> list[Path]:
    """The finished runs (``summary.json`` beside the config) at or below each path."""
    runs: list[Path] = []
    for path in paths:
        runs += [run for run in find_run_dirs(path) if (run / SUMMARY_NAME).is_file()]
    return runs


def compact(paths: Iterable[str | Path], suffix: str = ".xz") -> tuple[int, int, int]:
    """Compacts every finished run at or below ``paths``; (runs, records compressed now,
    bytes saved)."""
    runs = finished_runs(paths)
    count = saved = 0
    for run in runs:
        for record in run_records(run):
            before = record_file(record)
            if before is None or before.name.endswith(suffix):
                continue
            size = before.stat().st_size
            after = compact_record(record, suffix)
            count += 1
            saved += size - after.stat().st_size
    return len(runs), count, saved


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.compact", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("paths", nargs="+", metavar="RUN_OR_MULTIRUN_DIR")
    parser.add_argument("--format", choices=sorted(FORMATS), default="xz")
    args = parser.parse_args(argv)
    try:
        runs, count, saved = compact(args.paths, FORMATS[args.format])
    except (ReportError, OSError) as exc:
        print(f"[compact] error: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    print(
        f"[compact] {runs} finished runs: {count} records compressed ({args.format}), "
        f"{saved / 1e6:.1f} MB saved"
    )


if __name__ == "__main__":
    main()
