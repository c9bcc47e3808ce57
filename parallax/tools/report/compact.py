"""Compacts the records of runs that are over, for committing: each `metrics.jsonl` and
`eval.json` becomes `metrics.jsonl.xz` / `eval.json.xz`, which every reader of the report,
replay and analysis tools takes in place of the plain file
(`parallax.tools.report.runs.read_record`).

    python -m parallax.tools.report.compact RUN_OR_MULTIRUN_DIR…   # what reproduce.sh runs
    python -m parallax.tools.report.compact … --format gz          # gzip instead of xz
    python -m parallax.tools.report.compact … --keep replay        # what replays and reports read
    python -m parallax.tools.report.compact … --keep reports       # only what the reports read
    python -m parallax.tools.report.compact … --keep distance      # a replay's own: its learner's

Only runs that are over are compacted: finished (a `summary.json` beside the `config.yaml`) or
stopped by the trainer as diverged (its `diverged.json`); the trainer resumes an unfinished run
from its plain `metrics.jsonl`. In each, the run's `metrics.jsonl` and the
`eval.json` of the run and of the folders one level below it (`parallax-eval --out RUN/SUBDIR`).
A plain file is removed only once its compressed copy reads back the same text; the copy keeps
the plain file's modification time, so that "is the checkpoint newer than its eval" reads as
before. The output is deterministic (xz has no time stamp; gzip's is 0 and it names no file): the
same record always compresses to the same bytes. A record already compressed in the other format
is converted; figures and everything else are left alone (docs/results/runs/.gitignore keeps the
runs' figures out of git). ``--keep`` chooses what of each line of metrics.jsonl stays: ``all``
(the default) every key; ``replay`` the keys in READ_BY_REPORTS and what network_calls reads (the
fit statistics lm_* and the online distance error), each number kept to SIGNIFICANT_DIGITS, and the
keys in REPLAYED exactly, so that parallax-replay of the kept record is bit-identical to that of
the whole one; ``reports`` only the READ_BY_REPORTS keys, rounded: what the reports, the figures
and the analysis tools read of a run that nothing replays (a single position, a speed of the
continuous sweep). Rounding halves what is left (the reports print three or four digits). Both
leave a single position's ``mae`` and ``mae_recent`` to the one-entry per-position dicts that
repeat them (``REPEATED``), which ``read_metrics`` puts back.
``distance``, for the records of parallax-replay alone, only what the replay changed: the distance
learner's keys (FIT_KEYS, lm_*, which presentations it learnt from), rounded. A replay's eye is its
source's (``replayed_from`` in its summary), whose record keeps it and which the reports read for
a replay's eye curve; a record that is not a replay's is refused.
"""

from __future__ import annotations

import argparse
import gzip
import json
import lzma
import os
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from parallax.compressed import COMPRESSED, read_record, record_file, record_forms
from parallax.health import DIVERGED_NAME
from parallax.run_folder import RunLock, RunLocked, probe_all
from parallax.tools.report.runs import (
    METRICS_NAME,
    REPEATED,
    SUMMARY_NAME,
    ReportError,
    eval_files,
    find_run_dirs,
)

FORMATS = {"xz": ".xz", "gz": ".gz"}
#: The keys of a metrics.jsonl line that the reports (figures, Tables 2–3's curves), the
#: convergence, time-to-learn and collapse analyses and the continuous sweep's report read, and
#: the critic's norm, the statistic that overflows first in a diverged run (what its
#: diverged.json names), so that a thinned record still shows where.
READ_BY_REPORTS = (
    "presentation",
    "steps",
    "stage",
    "perturbed",
    "mae",
    "mae_per_position",
    "mae_recent",
    "mae_recent_per_position",
    "policy_critic_scale",
    "policy_critic_norm",
    "policy_entropy",
    "policy_actor_norm",
    "learnt_distance",
    "tracking_error_deg",
    "retinal_slip_deg",
)

#: What parallax-replay re-runs the distance learner on: which presentations it learnt from, the
#: distances and the eye-movement vectors s (each trial's last and best-encoded pan). Kept exact.
REPLAYED = (
    "presentation",
    "perturbed",
    "learnt_distance",
    "route",
    "distances",
    "pans",
    "best_pans",
)
#: What network_calls reads besides: the distance learner's fit statistics (keys with this
#: prefix) and the online distance error at the end of each block (FIT_KEYS).
FIT_PREFIX = "lm_"
FIT_KEYS = ("distance_error",)
#: What ``--keep distance`` keeps of a replay's line: where it is in the run, and its learner's.
REPLAY_OWN = ("presentation", "steps", "stage", "perturbed", "learnt_distance")
#: What ``--keep`` may name, from the most kept to the least.
KEEPS = ("all", "replay", "reports", "distance")

#: Digits a thinned record keeps of each number: the reports print three or four, so a relative
#: change of at most 5e-7 moves none of them (the 17 a float64 prints double the file).
SIGNIFICANT_DIGITS = 7


def rounded(value: Any) -> Any:
    """``value`` with every float in it (through lists and dicts) kept to SIGNIFICANT_DIGITS."""
    if isinstance(value, float):
        return float(f"{value:.{SIGNIFICANT_DIGITS}g}")
    if isinstance(value, list):
        return [rounded(item) for item in value]
    if isinstance(value, dict):
        return {key: rounded(item) for key, item in value.items()}
    return value


def without_repeats(line: dict[str, Any]) -> dict[str, Any]:
    """``line`` less each scalar its per-position dict of one entry repeats exactly (a single
    position's; REPEATED), which read_metrics puts back."""
    kept = dict(line)
    for scalar, per_position in REPEATED.items():
        values = kept.get(per_position)
        if isinstance(values, dict) and len(values) == 1 and scalar in kept:
            if next(iter(values.values())) == kept[scalar]:
                del kept[scalar]
    return kept


def kept_line(line: dict[str, Any], keep: str) -> dict[str, Any]:
    """What ``--keep replay``, ``reports`` or ``distance`` keeps of one metrics.jsonl line."""
    if keep == "reports":
        return without_repeats({k: rounded(v) for k, v in line.items() if k in READ_BY_REPORTS})
    if keep == "distance":
        return {
            k: rounded(v)
            for k, v in line.items()
            if k in REPLAY_OWN or k in FIT_KEYS or k.startswith(FIT_PREFIX)
        }
    return without_repeats(
        {
            k: v if k in REPLAYED else rounded(v)
            for k, v in line.items()
            if k in REPLAYED or k in READ_BY_REPORTS or k in FIT_KEYS or k.startswith(FIT_PREFIX)
        }
    )


def thin_metrics(run: Path, keep: str) -> None:
    """Rewrites ``run``'s metrics.jsonl (plain) with what ``keep`` keeps of each line; a record
    that keeps it all already is left as it is."""
    text = read_record(run / METRICS_NAME)
    kept = "".join(
        json.dumps(kept_line(json.loads(line), keep)) + "\n" for line in text.splitlines()
    )
    if kept == text:
        return
    partial = run / (METRICS_NAME + ".tmp")
    partial.write_text(kept, encoding="utf-8")
    partial.replace(run / METRICS_NAME)  # the plain file wins over a compressed one


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
    for stale in record_forms(path):
        if stale != target:
            stale.unlink(missing_ok=True)
    return target


def _unpack(path: Path, suffix: str) -> str:
    with COMPRESSED[suffix](path, "rt", encoding="utf-8") as handle:
        return handle.read()


def run_records(run: Path) -> list[Path]:
    """The records of a finished run that compaction keeps compressed, by their plain names."""
    records = [run / METRICS_NAME] if record_file(run / METRICS_NAME) is not None else []
    return records + eval_files(run)


def runs_over(paths: Iterable[str | Path]) -> list[Path]:
    """The runs that are over (``summary.json`` or ``diverged.json`` beside the config) at or
    below each path."""
    runs: list[Path] = []
    for path in paths:
        for run in find_run_dirs(path):
            if (run / SUMMARY_NAME).is_file() or (run / DIVERGED_NAME).is_file():
                runs.append(run)
    return runs


def compact(
    paths: Iterable[str | Path], suffix: str = ".xz", keep: str = "all"
) -> tuple[int, int, int]:
    """Compacts every run that is over at or below ``paths``, its metrics to what ``keep`` (one of
    KEEPS) keeps; (runs, records compressed now, bytes saved)."""
    if keep not in KEEPS:
        raise ValueError(f"keep must be one of {', '.join(KEEPS)}, got {keep!r}")
    runs = runs_over(paths)
    if keep == "distance":
        for run in runs:
            summary = json.loads((run / SUMMARY_NAME).read_text(encoding="utf-8"))
            if not summary.get("replayed_from"):
                raise ValueError(
                    f"{run}: not a replay (its summary names no replayed_from), so its record "
                    "holds its own eye: --keep distance would drop it"
                )
    # a run with a summary may be training again (lengthened): runs another process is writing
    # are refused before any is compacted, and each is locked while it is
    held = probe_all(runs)
    if held is not None:
        raise held
    count = saved = 0
    for run in runs:
        with RunLock(run, program="python -m parallax.tools.report.compact"):
            count, saved = _compact_run(run, suffix, keep, count, saved)
    return len(runs), count, saved


def _compact_run(run: Path, suffix: str, keep: str, count: int, saved: int) -> tuple[int, int]:
    """:func:`compact` of one run; the running counts."""
    sizes = {}
    metrics = record_file(run / METRICS_NAME)
    if keep != "all" and metrics is not None:
        sizes[run / METRICS_NAME] = metrics.stat().st_size
        thin_metrics(run, keep)
    for record in run_records(run):
        before = record_file(record)
        if before is None or before.name.endswith(suffix):
            continue
        size = sizes.get(record, before.stat().st_size)
        after = compact_record(record, suffix)
        count += 1
        saved += size - after.stat().st_size
    return count, saved


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.report.compact", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("paths", nargs="+", metavar="RUN_OR_MULTIRUN_DIR")
    parser.add_argument("--format", choices=sorted(FORMATS), default="xz")
    parser.add_argument(
        "--keep",
        choices=KEEPS,
        default="all",
        help="of each metrics line: every key, what replays and reports read, what reports read, "
        "or (a replay's record) its distance learner's keys",
    )
    args = parser.parse_args(argv)
    try:
        runs, count, saved = compact(args.paths, FORMATS[args.format], args.keep)
    except RunLocked as exc:
        print(f"[compact] error: {exc}; wait for it to end", file=sys.stderr)
        raise SystemExit(2) from None
    except (ReportError, ValueError) as exc:  # a path or a run it may not thin: nothing changed
        print(f"[compact] error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    except OSError as exc:
        print(f"[compact] error: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    print(
        f"[compact] {runs} runs finished or diverged: {count} records compressed ({args.format}), "
        f"{saved / 1e6:.1f} MB saved"
    )


if __name__ == "__main__":
    main()
