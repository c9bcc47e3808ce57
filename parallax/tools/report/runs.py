"""Loading finished runs for `parallax-report`: one job directory of `parallax-train` (its
config, `summary.json`, `metrics.jsonl` and the `eval.json` files of `parallax-eval`) as a `Run`.

A record may be kept compressed (`metrics.jsonl.xz`, `eval.json.gz`, …: the committed runs in
docs/results are, by `python -m parallax.tools.report.compact`); every reader here takes either
form, and names the record by its plain name (`eval_files`), so what the tools write does not
depend on it.

The numbers it reads are the paper's measures: the last-100-trial eye error of Tables 2–3 and
the distance error per range of Tables 4–5, before and after §5's perturbation. A job directory
with a config but no summary is a failed or unfinished job: it gets a `problem`, never an
exception, so that the report can list it. One the trainer stopped because its numbers stopped
being finite is over all the same: its `problem` says so, `Run.diverged` holds the trainer's
record of the stop (`parallax.health.DIVERGED_NAME`), and its figures before the perturbation,
if it got past it, are read as a finished run's.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException
from yaml import YAMLError

from parallax.compressed import read_record, record_file
from parallax.config import perturbation_start, run_settings, upgrade_saved
from parallax.health import DIVERGED_NAME
from parallax.metrics import position_label

SUMMARY_NAME = "summary.json"
EVAL_NAME = "eval.json"
METRICS_NAME = "metrics.jsonl"
RUN_CONFIG_NAME = "config.yaml"
HYDRA_CONFIG = Path(".hydra") / "config.yaml"
HYDRA_OVERRIDES = Path(".hydra") / "overrides.yaml"
#: Scalars of a metrics line that a single position's line repeats in a per-position dict of one
#: entry: a compacted record keeps the dict alone, and :func:`read_metrics` puts the scalar back.
REPEATED = {"mae": "mae_per_position", "mae_recent": "mae_recent_per_position"}


class ReportError(ValueError):
    """A bad input (a path that is not a run or multirun directory, an unreadable notes file)."""


def relpath(path: Path | str) -> str:
    """Relative to the working directory when below it (committed reports carry no home paths)."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def total_error(by_range: dict | None) -> float | None:
    """The total of a distance error per range (Tables 4–5's last column), if there is one."""
    return (by_range or {}).get("total")


def _load_yaml(path: Path) -> Any:
    """A YAML file as plain containers, read the way OmegaConf wrote it ('???' stays a string)."""
    return OmegaConf.to_container(OmegaConf.load(path), resolve=False)


def _load_json(path: Path) -> Any:
    # the trainer writes NaN for empty ranges; json reads it
    return json.loads(read_record(path))


@dataclass
class Run:
    """One job directory: its configuration, summary and evaluations, or why it has none."""

    path: Path
    config: dict
    summary: dict | None = None
    evals: list[dict] = field(default_factory=list)
    overrides: list[str] = field(default_factory=list)
    problem: str | None = None  # set for failed or unfinished jobs
    diverged: dict | None = None  # the trainer's record of a stop on non-finite numbers

    @property
    def flat(self) -> dict[str, Any]:
        return run_settings(self.config)

    @property
    def seed(self) -> Any:
        return self.config.get("seed")

    @property
    def lateral_labels(self) -> list[str]:
        lateral = (self.config.get("curriculum") or {}).get("lateral_positions") or []
        return [position_label(float(l)) for l in lateral]

    @property
    def total_presentations(self) -> int | None:
        value = (self.config.get("train") or {}).get("presentations")
        return int(value) if isinstance(value, (int, float)) else None

    @property
    def perturbation_start(self) -> int | None:
        """Presentation at which the perturbation is switched on (the trainer's rounding)."""
        return perturbation_start(self.config)

    # Tables 2–3: eye-movement error of the last trials before / after the perturbation.
    def phase_summary(self, phase: str) -> dict | None:
        """The summary of ``phase``, before or after §5's perturbation (for a run without one,
        "before" is its whole summary), None where the run has none: a diverged run has only
        the one before the perturbation, if it got past it."""
        if self.summary is None:
            kept = (self.diverged or {}).get("before_perturbation")
            return kept if phase == "before" else None
        before = self.summary.get("before_perturbation")
        if phase == "before":
            if before is not None:
                return before
            return self.summary if self.perturbation_start is None else None
        return self.summary if before is not None else None

    def last_trials(self, phase: str) -> dict | None:
        summary = self.phase_summary(phase)
        return None if summary is None else summary.get("last_trials")

    @property
    def photograph_evals(self) -> list[dict]:
        """The evaluations on the run's own kind of held-out textures (the photographs, unless
        the run trained on others), not those given textures of another kind."""
        return self.evals_on([])

    def evals_on(self, stimuli: list[str], split: str = "heldout") -> list[dict]:
        """The evaluations on textures set by these ``env.stimuli.*`` overrides of parallax-eval,
        of the photographs' ``split`` (parallax-eval --split: heldout, or train)."""
        return [
            e
            for e in self.evals
            if list(e.get("stimuli_overrides") or []) == list(stimuli)
            and (e.get("stimuli") or {}).get("split", "heldout") == split
        ]

    # Tables 4–5: the evaluation that measures the model in this phase, if one was made.
    def eval_for(
        self,
        phase: str,
        stimuli: list[str] | None = None,
        split: str = "heldout",
        most_photographs: bool = False,
    ) -> dict | None:
        """``stimuli``: the evaluations on textures of another kind (parallax-eval's overrides);
        ``split``: those on the photographs of this split. Of several evaluations of the phase's
        model, the run's own (the first found); with ``most_photographs``, the one with the most
        photographs per distance (parallax-eval --textures)."""
        evals = self.evals_on(stimuli or [], split)
        start = self.perturbation_start
        if phase == "before":
            fits = [
                e
                for e in evals
                if not e.get("perturbed")
                and (start is None or int(e.get("presentations", 0)) <= start)
            ]
        elif start is None:
            return None  # never trained under the perturbation: no "after" model
        else:
            fits = [e for e in evals if e.get("perturbed")]

        def rank(e: dict) -> tuple[int, int]:
            photographs = int(e.get("textures_per_distance") or 1) if most_photographs else 0
            return int(e.get("presentations", 0)), photographs

        return max(fits, key=rank, default=None)

    def final_eval(self) -> dict | None:
        """The evaluation of the final checkpoint in its final state (perturbed or not)."""
        if self.summary is None:
            return None
        ended_perturbed = self.summary.get("before_perturbation") is not None
        fits = [
            e
            for e in self.photograph_evals
            if bool(e.get("perturbed")) == ended_perturbed
            and int(e.get("presentations", -1)) == int(self.summary.get("presentations", -2))
        ]
        return fits[0] if fits else None

    def online_distance(self, phase: str) -> dict | None:
        summary = self.phase_summary(phase)
        return None if summary is None else (summary.get("distance_error") or {})

    def queue_distance(self, phase: str) -> dict | None:
        """The network scored on its own queue at the end of the phase (the paper's probable
        scoring of Tables 4–5); None for a run that predates it."""
        summary = self.phase_summary(phase)
        return None if summary is None else summary.get("distance_error_queue")

    def trained_eye_distance(self, phase: str) -> dict | None:
        """The eye as trained, scored on the grid: the learning policy's pans on the training
        photographs (``parallax-eval --split train``), the network as the phase left it (the
        paper's probable scoring of Tables 4–5); None without that evaluation."""
        found = self.eval_for(phase, split="train")
        return None if found is None else (found.get("distance_sampled") or {}).get("by_range")


def _is_run_dir(path: Path) -> bool:
    return (path / RUN_CONFIG_NAME).is_file() or (path / HYDRA_CONFIG).is_file()


def find_run_dirs(path: str | Path) -> list[Path]:
    """The run directories at or below `path`; a ReportError when there are none."""
    path = Path(path)
    if not path.exists():
        raise ReportError(f"{path} does not exist")
    if not path.is_dir():
        raise ReportError(f"{path} is not a directory (give a run or multirun directory)")
    if _is_run_dir(path):
        return [path]
    found = []
    for dirpath, dirnames, _ in os.walk(path):
        # .hydra, .submitit and TensorBoard folders hold no runs
        dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and d != "tb")
        here = Path(dirpath)
        if here != path and _is_run_dir(here):
            found.append(here)
            dirnames[:] = []
    if not found:
        raise ReportError(
            f"{path} is not a run or multirun directory: no {RUN_CONFIG_NAME} "
            f"(or {HYDRA_CONFIG}) in it or below it"
        )
    return found


def _progress(path: Path, total: int | None) -> str:
    """'12 of 400 presentations logged' from the last line of metrics.jsonl."""
    metrics = path / METRICS_NAME
    done = 0
    if record_file(metrics) is not None:
        lines = [line for line in read_record(metrics).splitlines() if line.strip()]
        if lines:
            try:
                done = int(json.loads(lines[-1]).get("presentation", 0))
            except (json.JSONDecodeError, AttributeError, TypeError, ValueError):
                done = 0
    of = f" of {total}" if total is not None else ""
    checkpoint = "; checkpoint.pt present, resumable" if (path / "checkpoint.pt").is_file() else ""
    return f"{done}{of} presentations logged{checkpoint}"


def eval_files(path: Path) -> list[Path]:
    """eval.json in the run directory and one level below (parallax-eval --out RUN/SUBDIR), each
    by its plain name, also when it is kept compressed (read it with :func:`read_record`)."""
    files = [path / EVAL_NAME] if record_file(path / EVAL_NAME) is not None else []
    for sub in sorted(
        p for p in path.iterdir() if p.is_dir() and not p.name.startswith(".") and p.name != "tb"
    ):
        if record_file(sub / EVAL_NAME) is not None:
            files.append(sub / EVAL_NAME)
    return files


def launch_overrides(path: Path) -> list[str] | None:
    """The Hydra overrides a job directory was launched with (its .hydra/overrides.yaml); None
    where it has none that can be read."""
    if not (path / HYDRA_OVERRIDES).is_file():
        return None
    try:
        return [str(o) for o in (_load_yaml(path / HYDRA_OVERRIDES) or [])]
    except (YAMLError, OmegaConfBaseException):
        return None


def load_run(path: Path) -> Run:
    """Read one job directory; problems become `Run.problem`, not exceptions."""
    overrides = launch_overrides(path) or []
    started = (path / RUN_CONFIG_NAME).is_file()
    config_path = path / RUN_CONFIG_NAME if started else path / HYDRA_CONFIG
    try:
        config = upgrade_saved(_load_yaml(config_path))
    except (YAMLError, OmegaConfBaseException) as exc:
        return Run(
            path,
            {},
            overrides=overrides,
            problem=f"unreadable {config_path.name}: {str(exc).splitlines()[0]}",
        )
    if not isinstance(config, dict):
        return Run(path, {}, overrides=overrides, problem=f"{config_path} is not a mapping")
    run = Run(path, config, overrides=overrides)
    if not started:
        run.problem = "failed before training started (no config.yaml from the trainer)"
        return run
    summary_path = path / SUMMARY_NAME
    if not summary_path.is_file() and (path / DIVERGED_NAME).is_file():
        try:
            run.diverged = _load_json(path / DIVERGED_NAME)
            run.problem = (
                f"diverged: stopped at presentation {run.diverged['stopped_at']}, not finite "
                f"since {run.diverged['unhealthy_since']} ({run.diverged['problems']})"
            )
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            run.diverged = None
            run.problem = f"unreadable {DIVERGED_NAME}: {exc!r}"
        return run
    if not summary_path.is_file():
        run.problem = (
            f"failed or unfinished: no {SUMMARY_NAME}; {_progress(path, run.total_presentations)}"
        )
        return run
    try:
        run.summary = _load_json(summary_path)
    except json.JSONDecodeError as exc:
        run.problem = f"unreadable {SUMMARY_NAME}: {exc}"
        return run
    done, total = run.summary.get("presentations"), run.total_presentations
    if total is not None and isinstance(done, int) and done < total:
        run.problem = f"unfinished: {SUMMARY_NAME} covers {done} of {total} presentations"
        run.summary = None
        return run
    for eval_path in eval_files(path):
        try:
            result = _load_json(eval_path)
        except json.JSONDecodeError:
            continue  # an eval being written right now; the report uses the summary instead
        result["_path"] = str(eval_path)
        run.evals.append(result)
    return run


def read_metrics(path: Path) -> list[dict]:
    """metrics.jsonl's records, plain or compressed (:func:`record_file`), each with the scalars
    a compacted record left to its per-position dict (REPEATED); a torn last line (a run killed
    while writing) is skipped."""
    metrics = Path(path) / METRICS_NAME
    if record_file(metrics) is None:
        return []
    records = []
    for line in read_record(metrics).splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        for scalar, per_position in REPEATED.items():
            values = record.get(per_position)
            if scalar not in record and isinstance(values, dict) and len(values) == 1:
                record[scalar] = next(iter(values.values()))
        records.append(record)
    return records


def eval_run_dir(eval_dir: str | Path, stored: str) -> Path:
    """The run an evaluation in ``eval_dir`` measured, from the ``run_dir`` its eval.json
    stored: as stored (absolute, or relative to the working directory, as older evaluations
    kept it), else the evaluation's own folder or the one above it (an eval kept beside or
    inside its run, wherever the two were moved)."""
    eval_dir, path = Path(eval_dir), Path(stored)
    for candidate in ([path] if stored else []) + [eval_dir, eval_dir.parent]:
        if (candidate / "config.yaml").is_file():
            return candidate
    raise FileNotFoundError(
        f"{eval_dir}/eval.json measured the run {stored}, which holds no config.yaml here "
        "(nor does the evaluation's folder or the one above it)"
    )
