"""parallax-replay: the distance learner (paper §3.5–3.5.2, §6) alone, on a finished run's stream.

The distance learner never acts on the world: the eye-movement vectors s it sees depend only on
the world, the coder and the policy. So a run's metrics.jsonl, which logs every s with its true
distance in order, lets the learner be re-run with another weighting y, queue size c, weighting
on/off or readout (``train.distance_readout``: s as every pan readout reads it is logged), and
the result is exactly what `parallax-train` would have reported with that setting and the same
seed (tests/tools/test_replay.py checks this bit for bit). That makes the y, c and
weighting ablations of Table 4 cost seconds per setting instead of a full run each.

    parallax-replay SOURCE_RUN_OR_MULTIRUN --out DIR distance.y=0,0.5,1,2
        distance.queue_size=100,300
    parallax-replay … --until-perturbation     # only the part before §5's perturbation

Each source run × each combination of the comma-separated values becomes DIR/<run>/<overrides>/
with config.yaml (the source's, with the overrides applied), summary.json (the source's eye
metrics, this learner's online distance errors), metrics.jsonl (the source's lines with this
learner's online error and fit statistics: the record a run trained with these settings writes,
byte for byte), the source's checkpoints with this learner and, where the source has
parallax-eval results with their eye-movement samples, the same evals with this learner's
distance predictions, so
`parallax-report DIR` tables them like runs. Each of these folders has one writer
(:mod:`parallax.run_folder`): all are locked before the first is written.

    parallax-replay RUN --out DIR --as-launched distance.warm_start=false

writes the replay as the run `parallax-train` writes when launched with the source's own
overrides less the replayed settings (and less any the rest already give): DIR/<those
overrides>/ with their .hydra/overrides.yaml and no replay provenance in its summary. It is
refused unless that launch composes exactly the replay's settings, e.g. a run trained with a
distance setting that its experiment file has since changed, replayed with the file's value.
"""

from __future__ import annotations

import argparse
import copy
import functools
import itertools
import json
import sys
from collections.abc import Iterable, Sequence
from importlib import resources
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from parallax import checkpoint
from parallax.checkpoint import BEFORE_PERTURBATION_NAME, CHECKPOINT_NAME
from parallax.config import (
    CONFIG_MODULE,
    RUN_CONFIG_NAME,
    compose,
    flatten,
    load_run_config,
    result_settings,
    run_name,
    run_settings,
)
from parallax.metrics import DistanceErrorTracker, finite_or_none
from parallax.parts import body_walkers, distance_learner, worlds
from parallax.readouts import READOUTS
from parallax.run_folder import RunLock, RunLocked, write_atomic
from parallax.tools.console import footer, header, progress
from parallax.tools.report.groups import mean_sd
from parallax.tools.report.runs import (
    HYDRA_OVERRIDES,
    METRICS_NAME,
    SUMMARY_NAME,
    ReportError,
    eval_files,
    find_run_dirs,
    launch_overrides,
    read_metrics,
    read_record,
)
from parallax.writable import folder_problem

#: Settings a replay may change: the distance learner's, and the body's walk to the panel.
REPLAYABLE_PREFIXES = ("distance.", "env.walk.")


class ReplayError(ValueError):
    """A source run or an override that cannot be replayed; the message names it."""


def parse_sweep(overrides: Sequence[str]) -> list[list[str]]:
    """['distance.y=1,2', 'distance.weighting=false'] → every combination, each a list of dotlist
    items; ``open_setting=NAME`` (conf/open_setting/NAME.yaml) gives that file's settings."""
    axes = []
    for item in overrides:
        key, sep, values = item.partition("=")
        if not sep or not key or not values:
            raise ReplayError(
                f"{item!r} is neither an existing directory nor an override KEY=VALUE[,VALUE…]"
            )
        if key.lstrip("+") == "open_setting":
            axes.append([open_setting_items(name) for name in values.split(",")])
            continue
        _check_replayable(item, key)
        axes.append([[f"{key}={v}"] for v in values.split(",")])
    return [sum(combo, []) for combo in itertools.product(*axes)] if axes else [[]]


def _check_replayable(item: str, key: str) -> None:
    # the readout only picks which of the logged pans of each trial s is built from; the
    # walk to the panel comes after the sweep, with its own random stream
    if not (key.startswith(REPLAYABLE_PREFIXES) or key == "train.distance_readout"):
        raise ReplayError(
            f"override {item!r}: only distance.*, env.walk.* and train.distance_readout "
            "can be replayed (anything else changes the eye movements: train a new run)"
        )


def open_setting_items(name: str) -> list[str]:
    """The settings conf/open_setting/NAME.yaml sets, as dotlist items (each replayable)."""
    path = resources.files(CONFIG_MODULE) / "open_setting" / f"{name}.yaml"
    if not path.is_file():
        raise ReplayError(f"open_setting={name}: no conf/open_setting/{name}.yaml")
    settings = flatten(OmegaConf.to_container(OmegaConf.create(path.read_text())))
    items = [f"{key}={json.dumps(value)}" for key, value in settings.items()]
    for item in items:
        _check_replayable(f"open_setting={name} ({item})", item.partition("=")[0])
    return items


def read_stream(run_dir: Path) -> list[dict]:
    """The run's metrics.jsonl records, which must carry the eye-movement vectors s."""
    records = read_metrics(run_dir)
    if records and "pans" not in records[0]:
        raise ReplayError(
            f"{run_dir / METRICS_NAME} has no eye-movement vectors: the run predates "
            "parallax-replay (logging of s); train it again to replay it"
        )
    return records


def replay(
    run_dir: str | Path,
    overrides: Sequence[str] = (),
    until_perturbation: bool = False,
    bar: Any = None,
    rescore: Sequence[str] | None = None,
    so_far: bool = False,
) -> dict:
    """The source run's summary with the distance learner re-run under `overrides`.

    ``until_perturbation``: if the run was perturbed, replay only the presentations before §5's
    perturbation and present the result as a run of that length without one (config and summary
    alike), so that the ablation tables of parallax-report compare the unperturbed models (Table 4,
    not Table 5). A run never perturbed is replayed whole. ``bar``: a progress bar that moves on
    by each presentation replayed. ``rescore``: the folders (relative to the run, "." for its own)
    of the evaluations to score again with the replayed learner; None: every one. ``so_far``: a
    run still training is replayed as far as its record goes (its learner's fits and online
    predictions, for the analyses; no summary of its own, so nothing to write as a run).
    """
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    summary_path = run_dir / SUMMARY_NAME
    if not summary_path.is_file() and not so_far:
        raise ReplayError(f"{run_dir} has no {SUMMARY_NAME}: replay finished runs only")
    try:
        cfg.merge_with_dotlist(list(overrides))
    except Exception as exc:  # OmegaConf's errors are long; one line naming the value is enough
        raise ReplayError(
            f"cannot apply {list(overrides)} to {run_dir}: {str(exc).splitlines()[0]}"
        ) from None
    records = read_stream(run_dir)
    summary = (
        json.loads(summary_path.read_text())
        if summary_path.is_file()
        else {"presentations": len(records), "before_perturbation": None}
    )
    if int(cfg.train.threads) > 0:
        # as in training and parallax-eval: replays side by side, each with several intra-op
        # threads, would oversubscribe the cores
        torch.set_num_threads(int(cfg.train.threads))
    learner = distance_learner(cfg)
    tracker = _OnlineHistory(window=int(cfg.metrics.distance_window))
    before = before_learner = None
    if len(records) < int(summary["presentations"]):
        raise ReplayError(
            f"{run_dir / METRICS_NAME} has {len(records)} presentations, the summary "
            f"{summary['presentations']}: the log is incomplete"
        )
    readout = str(cfg.train.distance_readout)
    if readout not in READOUTS:
        raise ReplayError(
            f"train.distance_readout must be one of {', '.join(READOUTS)}, got {readout!r}"
        )
    key = READOUTS[readout].key
    if records and key not in records[0]:
        raise ReplayError(
            f"{run_dir / METRICS_NAME} has no {key} (the run predates their logging): "
            f"it cannot be replayed with train.distance_readout={readout}"
        )
    before_tracker = last_stats = before_stats = None
    body = _Body(cfg) if learner.target_source.walks else None
    before_grown = False
    fits: list[tuple[int, float, float]] = []  # (presentation, epochs, stopped by max_fail)
    lines: list[dict] = []  # the record as training with these settings would have written it
    for record in records[: int(summary["presentations"])]:
        if bar is not None:
            bar.update(1)
        if record["perturbed"] and before is None:
            before = tracker.by_range()
            before_learner = copy.deepcopy(
                learner
            )  # the model of checkpoint_before_perturbation.pt
            before_tracker, before_stats = copy.deepcopy(tracker), last_stats
            before_grown = body is not None and body.grown
            if until_perturbation:
                break
        if body is not None:  # as the trainer: the spurt after the checkpoint at the switch
            body.at_presentation(int(record["presentation"]) - 1)
        # a planned route's s is partial: the network learns from full sweeps only, as in training
        if record["learnt_distance"] and record.get("route") is None:
            tracker.presentation = int(record["presentation"])
            if body is not None:  # the panels where the sweep saw them, for the walks
                body.place(record["distances"])
            pans = np.atleast_2d(np.asarray(record[key], dtype=np.float64))
            distances = np.asarray(record["distances"], dtype=np.float64)
            stats, _ = learner.target_source.learn(learner, tracker, pans, distances, body)
            last_stats = stats or last_stats
            if stats.get("trained"):
                fits.append((tracker.presentation, stats["epochs"], stats["stopped_max_fail"]))
        lines.append(replayed_line(record, tracker.by_range(), last_stats or {}))
    cut = until_perturbation and summary.get("before_perturbation") is not None
    truths = {
        "before": None if body is None else functools.partial(body.truths, grown=before_grown),
        "final": None if body is None else functools.partial(body.truths, grown=body.grown),
    }
    evals = _rescore_evals(
        run_dir, summary, before_learner, None if cut else learner, readout, truths, rescore
    )
    if body is not None:
        body.close()
    if cut:
        cut_summary = _cut_at_perturbation(
            cfg, summary, tracker, before_learner, run_dir, overrides
        )
        return {**cut_summary, "evals": evals, "fits": fits, "metrics": lines}
    summary["distance_error"] = tracker.by_range()
    summary["distance_error_queue"] = learner.queue_error()
    if summary.get("before_perturbation") is not None:
        summary["before_perturbation"]["distance_error"] = before or {}
        summary["before_perturbation"]["distance_error_queue"] = (
            before_learner.queue_error() if before_learner is not None else {}
        )
    summary["replayed_from"] = str(run_dir)
    summary["replay_overrides"] = list(overrides)
    checkpoints = {
        CHECKPOINT_NAME: (learner, tracker, last_stats),
        BEFORE_PERTURBATION_NAME: (before_learner, before_tracker, before_stats),
    }
    return {
        "config": cfg,
        "summary": summary,
        "evals": evals,
        "online": tracker.history,
        "fits": fits,
        "source": run_dir,
        "checkpoints": {name: parts for name, parts in checkpoints.items() if parts[0] is not None},
        "metrics": lines,
    }


def replayed_line(record: dict, distance_error: dict, stats: dict) -> dict:
    """A metrics.jsonl line of the source with the replayed distance learner's part: the online
    error by range and the last fit's statistics (lm_*), where and as the trainer writes them
    (:class:`parallax.record.PresentationRecord`); the rest is the source's."""
    line = {k: v for k, v in record.items() if not k.startswith("lm_")}
    line["distance_error"] = distance_error
    return {**line, **{f"lm_{k}": v for k, v in stats.items()}}


def _replayed_checkpoint(
    source: Path, learner, tracker, stats, before_perturbation, config: DictConfig
) -> dict:
    """The source's checkpoint with the replayed distance learner (and its online-error tracker)
    in place of the trained one: the eye, coder and policy are the source's, as in the replay.
    It records the replay's settings (``config``), which it now holds."""
    state = checkpoint.load(source, map_location="cpu")
    if "config" in state:
        state["config"] = OmegaConf.to_container(config, resolve=True)
    state["experiment"]["distance"] = learner.state_dict()
    state["dist"] = tracker.state_dict()
    state["last_distance_stats"] = stats
    if "before_perturbation" in state and state["before_perturbation"] is not None:
        state["before_perturbation"] = before_perturbation
    return state


class _OnlineHistory(DistanceErrorTracker):
    """The online error tracker, also keeping every prediction (presentation, d̂, truth): the
    learning curve of a replay (e.g. its recovery after a growth spurt)."""

    def __init__(self, window: int) -> None:
        super().__init__(window=window)
        self.presentation = 0
        self.history: list[tuple[int, float, float]] = []

    def record(self, predicted_m: float, true_m: float, at_m: float | None = None) -> None:
        super().record(predicted_m, true_m, at_m)
        self.history.append((self.presentation, float(predicted_m), float(true_m)))


class _Body:
    """The bodies of a replayed run that walks (distance.targets=odometry): its worlds (physics
    only) and its walkers with the trainer's seeds, as the target source's ``bodies``."""

    def __init__(self, cfg: DictConfig) -> None:
        self.worlds = worlds(cfg, [float(l) for l in cfg.curriculum.lateral_positions])
        self.walkers = body_walkers(cfg)

    @property
    def grown(self) -> bool:
        return self.walkers[0].grown

    def at_presentation(self, index: int) -> None:
        """Presentation ``index`` (0-based) is next: the bodies grown or not, as in training."""
        for walker in self.walkers:
            walker.at_presentation(index)

    def place(self, distances: Sequence[float]) -> None:
        """Each robot's panel at its distance of the sweep, for the walks after it."""
        for world, d in zip(self.worlds, distances, strict=True):
            world.physics.set_stimulus(world.physics.texture_index(), float(d))

    def truths(self, source, distances: Sequence[float], grown: bool) -> list[float]:
        """A perfect learner's answers for panels at ``distances`` with the body grown or not."""
        walker = copy.deepcopy(self.walkers[0])
        walker.grown = grown
        body = SimpleNamespace(worlds=self.worlds[:1], walkers=[walker])
        return source.truths(distances, body).tolist()

    def close(self) -> None:
        for world in self.worlds:
            world.close()


def _rescore_evals(
    run_dir: Path,
    summary: dict,
    before_learner,
    final_learner,
    readout: str = "last",
    truths: dict | None = None,
    folders: Sequence[str] | None = None,
) -> dict[str, dict]:
    """The source's parallax-eval results with the distances re-predicted by the replayed
    learners, on the very eye movements the eval recorded (eval.json "samples"); keyed by the
    eval file's path relative to the run. The frozen eye is the source's, so the eye-movement
    numbers are kept as they are. Evals that read s otherwise than ``readout`` are left out.
    ``truths`` ("before", "final"): for odometry targets, (source, distances) → the slip-free
    readings of the body at that checkpoint; None: the distances. ``folders``: only the evals in
    these folders (relative to the run); None: every one."""
    from parallax.tools.evaluate import distance_results

    rescored = {}
    start = (summary.get("before_perturbation") or {}).get("presentations")
    for path in eval_files(run_dir):
        if folders is not None and str(path.parent.relative_to(run_dir)) not in folders:
            continue
        result = json.loads(read_record(path))
        samples = _eval_samples(result, readout)
        if not samples:
            continue  # an eval without the samples, or with s read out otherwise only
        at = int(result.get("presentations", -1))
        if result.get("perturbed") or start is None:
            learner = final_learner if at == int(summary["presentations"]) else None
            truth = (truths or {}).get("final")
        else:
            learner = before_learner if at == start else None
            truth = (truths or {}).get("before")
        if learner is None or not learner.is_ready:
            continue
        for key, kept in samples.items():
            at_truth = None if truth is None else truth(learner.target_source, kept["distances"])
            result[key] = distance_results(learner, kept["pans"], kept["distances"], at_truth)
        if result.get("readout", "last") != readout:
            # the distances are this readout's; the eye-movement errors stay the eval's own
            result["eye_readout"], result["readout"] = result.get("readout", "last"), readout
        result["replayed_from"] = str(path)
        rescored[str(path.relative_to(run_dir))] = result
    return rescored


def _eval_samples(result: dict, readout: str) -> dict[str, dict]:
    """eval.json key → the eye's s vectors, read out as ``readout``, and the distances that eval
    scored (or would have): the greedy eye's, and the sampled policy's where the eval scored
    them; empty where the eval kept no such vectors."""
    sampled = (result.get("distance_sampled") or {}).get("samples")
    if sampled and result.get("readout", "last") == readout:
        # the learning policy's eye movements, scored as the greedy eye's are
        return {**_greedy_samples(result, readout), "distance_sampled": sampled}
    return _greedy_samples(result, readout)


def _greedy_samples(result: dict, readout: str) -> dict[str, dict]:
    names = {"grid": "distance", "between": "distance_between_grid"}
    by_readout = result.get("greedy_samples_by_readout") or {}
    if readout in by_readout:
        kept = result["greedy_samples"]
        return {
            names[k]: {"pans": v["pans"], "distances": kept[k]["distances"]}
            for k, v in by_readout[readout].items()
            if k in names
        }
    if result.get("readout", "last") != readout:
        return {}
    if "greedy_samples" in result:
        return {names[k]: v for k, v in result["greedy_samples"].items() if k in names}
    return {
        k: result[k]["samples"]
        for k in ("distance", "distance_between_grid")
        if "samples" in (result.get(k) or {})
    }


def _cut_at_perturbation(
    cfg: DictConfig,
    summary: dict,
    tracker: DistanceErrorTracker,
    learner,
    run_dir: Path,
    overrides: Sequence[str],
) -> dict:
    before = summary["before_perturbation"]
    cut = {k: v for k, v in summary.items() if k not in ("before_perturbation", "timing")}
    cut.update(before)
    cut["distance_error"] = tracker.by_range()
    cut["distance_error_queue"] = learner.queue_error() if learner is not None else {}
    cut["before_perturbation"] = None
    cut["replayed_from"], cut["replay_overrides"] = str(run_dir), [*overrides, "until_perturbation"]
    cfg.train.presentations = int(before["presentations"])
    cfg.perturbation.merge_with(
        {"camera_rotation_deg": 0.0, "blur_sigma": 0.0, "start_fraction": None}
    )
    return {"config": cfg, "summary": cut}


def find_sources(paths: Iterable[str | Path]) -> list[Path]:
    """Finished runs (summary.json beside config.yaml) at or below each path."""
    found: list[Path] = []
    for path in map(Path, paths):
        if not path.is_dir():
            raise ReplayError(f"{path} is not a directory (give a run or multirun directory)")
        try:
            runs = [run for run in find_run_dirs(path) if (run / SUMMARY_NAME).is_file()]
        except ReportError:
            runs = []
        if not runs:
            raise ReplayError(
                f"{path} holds no finished run ({RUN_CONFIG_NAME} with {SUMMARY_NAME})"
            )
        found += runs
    return found


def check_checkpoints(sources: Iterable[Path]) -> None:
    """Every checkpoint a whole replay copies (:func:`write_replay`) can be read and is its
    run's; else a ReplayError naming it, before any replay is written."""
    for source in sources:
        cfg = load_run_config(source)
        for name in (CHECKPOINT_NAME, BEFORE_PERTURBATION_NAME):
            if (source / name).is_file():
                try:
                    checkpoint.read(source / name, config=cfg)
                except checkpoint.CheckpointError as exc:
                    raise ReplayError(
                        f"{exc}; the replay writes it again with the replayed learner: move it "
                        "aside to replay without it"
                    ) from None


def _launch_settings(cfg: DictConfig) -> dict:
    """What makes two runs the same run: their results' settings, seed included."""
    return result_settings(run_settings(OmegaConf.to_container(cfg, resolve=True)), seed=True)


def launched_as(source: Path, combo: Sequence[str], cfg: DictConfig) -> list[str]:
    """The overrides with which `parallax-train` writes the replay of ``source`` under ``combo``
    (whose config is ``cfg``): the source's own, less the replayed settings and less those the
    rest already give (its experiment and seed kept). ReplayError unless they compose ``cfg``."""
    path = source / HYDRA_OVERRIDES
    listed = launch_overrides(source)
    if listed is None:
        raise ReplayError(f"{source}: no readable {HYDRA_OVERRIDES}, so no launch to replay it as")
    replayed = {item.partition("=")[0] for item in combo}
    kept = [o for o in listed if o.partition("=")[0].lstrip("+~") not in replayed]
    wanted = _launch_settings(cfg)

    def composes(overrides: list[str]) -> dict:
        try:
            return _launch_settings(compose(overrides))
        except Exception as exc:  # Hydra's errors are long: the first line names the override
            raise ReplayError(f"{path}: {str(exc).splitlines()[0]}") from None

    if composes(kept) != wanted:
        launch = " ".join(kept) or "(no overrides)"
        raise ReplayError(
            f"{source} replayed with {' '.join(combo)}: `parallax-train {launch}` composes other "
            "settings, so the replay is not a run of that launch"
        )
    for override in list(kept):
        if override.partition("=")[0].lstrip("+~") in ("experiment", "seed"):
            continue
        fewer = [o for o in kept if o != override]
        if composes(fewer) == wanted:
            kept = fewer
    return kept


def final_eval_path(relative: str) -> str:
    """Where a before-perturbation eval goes in a replay cut at the perturbation, whose final
    model it scored: eval_before/eval.json → eval.json, eval_before_X/… → eval_X/… (as the
    reproduction names the final model's evals); any other path stays."""
    first, sep, rest = relative.partition("/")
    if first == "eval_before" and sep:
        return rest
    if first.startswith("eval_before_") and sep:
        return f"eval_{first.removeprefix('eval_before_')}/{rest}"
    return relative


def write_replay(result: dict, out_dir: Path, launched: Sequence[str] | None = None) -> None:
    """The replay as a run directory: config, summary, the rescored evals and, for a whole
    replay, the source's checkpoints with the replayed learner (so parallax-eval runs on it).
    ``launched``: the overrides of the launch it stands for (:func:`launched_as`), written as
    Hydra writes them, the summary without the replay's provenance."""
    out_dir.mkdir(parents=True, exist_ok=True)
    if launched is not None:
        for key in ("replayed_from", "replay_overrides"):
            result["summary"].pop(key, None)
        (out_dir / HYDRA_OVERRIDES).parent.mkdir(exist_ok=True)
        write_atomic(out_dir / HYDRA_OVERRIDES, OmegaConf.to_yaml(list(launched)))
    for name, (learner, tracker, stats) in result.get("checkpoints", {}).items():
        source = result["source"] / name
        if source.is_file():
            state = _replayed_checkpoint(
                source,
                learner,
                tracker,
                stats,
                result["summary"].get("before_perturbation"),
                result["config"],
            )
            checkpoint.save_atomic(state, out_dir / name)
    write_atomic(out_dir / RUN_CONFIG_NAME, OmegaConf.to_yaml(result["config"], resolve=True))
    if result.get("metrics"):  # the lines as the trainer writes them (parallax.run_log)
        metrics = "".join(json.dumps(line) + "\n" for line in result["metrics"])
        write_atomic(out_dir / METRICS_NAME, metrics)
    summary = finite_or_none(result["summary"])  # strict JSON, as the trainer's
    write_atomic(out_dir / SUMMARY_NAME, json.dumps(summary, indent=2, allow_nan=False) + "\n")
    cut = result["summary"].get("before_perturbation") is None
    for relative, evaluation in result.get("evals", {}).items():
        if cut and not evaluation.get("perturbed"):
            relative = final_eval_path(relative)
        (out_dir / relative).parent.mkdir(parents=True, exist_ok=True)
        write_atomic(out_dir / relative, json.dumps(evaluation, indent=2) + "\n")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="parallax-replay", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "sources",
        nargs="+",
        metavar="RUN_OR_MULTIRUN_DIR_OR_OVERRIDE",
        help="finished runs (or folders holding them) and distance.KEY=V1,V2 overrides",
    )
    parser.add_argument("--out", required=True, help="folder for the replayed runs")
    parser.add_argument(
        "--until-perturbation",
        action="store_true",
        help="replay only the presentations before the perturbation, if any (Table 4's models)",
    )
    parser.add_argument(
        "--as-launched",
        action="store_true",
        help="write each replay as the run of the source's launch less the replayed settings "
        "(OUT/<its overrides>/, .hydra/overrides.yaml); refused unless that launch composes it",
    )
    parser.add_argument(
        "--rescore",
        action="append",
        metavar="EVAL_FOLDER",
        help="score again only this evaluation of each source (its folder relative to the run, "
        "'.' for the run's own; repeat for more); default: every one",
    )
    # intermixed: the overrides may come after the options (as launch/ablation_lib.sh puts them)
    args = parser.parse_intermixed_args(argv)
    # Hydra's run directories have '=' in their names: what exists is a path, the rest overrides.
    paths = [s for s in args.sources if Path(s).exists()]
    overrides = [s for s in args.sources if not Path(s).exists()]
    locks: list[RunLock] = []
    try:
        combos = parse_sweep(overrides)
        sources = find_sources(paths)
        out = Path(args.out)
        problem = folder_problem(out)
        if problem:
            raise ReplayError(f"--out {args.out}: {problem}; choose another folder")
        if not args.until_perturbation:
            check_checkpoints(sources)
        # every replayed run folder has one writer (parallax.run_folder): all are locked before
        # the first is written
        launches: dict[tuple[Path, tuple[str, ...]], list[str]] = {}
        if args.as_launched:
            if args.until_perturbation:
                raise ReplayError("--as-launched replays whole runs: drop --until-perturbation")
            for s in sources:
                saved = load_run_config(s)
                for c in combos:
                    cfg = saved.copy()
                    cfg.merge_with_dotlist(list(c))
                    launches[s, tuple(c)] = launched_as(s, c, cfg)
        targets = [_target(out, s, c, launches) for s in sources for c in combos]
        if len(set(targets)) < len(targets):
            raise ReplayError("two replays would be the same launch's run: replay them apart")
        locks = _lock_all(targets)
        totals: dict[
            str, dict[str, list[float]]
        ] = {}  # combo → what was scored → one total per source
        lengths = {
            s: int(json.loads((s / SUMMARY_NAME).read_text())["presentations"]) for s in sources
        }
        header(
            "parallax-replay",
            f"the distance learner re-run on the eye movements of {len(sources)} finished run"
            + "s" * (len(sources) != 1),
            overrides=" | ".join(" ".join(c) or "(as trained)" for c in combos),
            presentations=f"{sum(lengths.values())} per setting"
            + (", up to the perturbation" if args.until_perturbation else ""),
            output=out.resolve(),
        )
        bar = progress(total=sum(lengths.values()) * len(combos), desc="presentations")
        written = []
        for source in sources:
            for combo in combos:
                target = _target(out, source, combo, launches)
                start = bar.n
                result = replay(source, combo, args.until_perturbation, bar, args.rescore)
                bar.update(start + lengths[source] - bar.n)  # the rest, if cut at the perturbation
                write_replay(result, target, launches.get((source, tuple(combo))))
                written.append(target)
                scored, label = replay_totals(result), " ".join(combo) or "(as trained)"
                for what, total in scored.items():
                    totals.setdefault(label, {}).setdefault(what, []).append(total)
                bar.write(
                    f"[replay] {source.name} {label}: distance error "
                    f"{_format_totals(scored) or '— (queue never filled)'}",
                    file=sys.stdout,
                )
        bar.close()
        if len(sources) > 1:
            for combo, scored in totals.items():
                spread = {what: f"{mean_sd(v)} % (n={len(v)})" for what, v in scored.items()}
                print(
                    f"[replay] {combo}, mean ± sd over runs: "
                    + "; ".join(f"{what} {text}" for what, text in spread.items()),
                    flush=True,
                )
        footer("parallax-replay", written)
    except (ReplayError, FileNotFoundError, ValueError) as exc:
        # bad input (a folder that is no run, an override it cannot take, a stale run config)
        for lock in locks:
            lock.release(restore=True)  # the folders not written yet, as they were
        print(f"parallax-replay: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        sys.exit(2)
    finally:
        for lock in locks:
            lock.release()


def _target(out: Path, source: Path, combo: Sequence[str], launches: dict) -> Path:
    """A replay's folder: OUT/<source>/<overrides>, or as launched, OUT/<launch's overrides>
    named as Hydra names a run's folder (sorted, joined by commas)."""
    launched = launches.get((source, tuple(combo)))
    if launched is None:
        return out / source.name / run_name(",".join(combo))
    return out / run_name(",".join(sorted(launched)))


def _lock_all(folders: Sequence[Path]) -> list[RunLock]:
    """Locks on all ``folders``, or none: a ReplayError naming the first another process holds,
    the folders left as they were."""
    locks: list[RunLock] = []
    try:
        for folder in dict.fromkeys(folders):
            locks.append(RunLock(folder, program="parallax-replay").acquire())
    except RunLocked as exc:
        for lock in reversed(locks):
            lock.release(restore=True)
        raise ReplayError(f"{exc}; wait for it to end, or choose another --out") from None
    return locks


def replay_totals(result: dict) -> dict[str, float]:
    """The replayed learner's total distance errors (%): online over the training stream, then
    each rescored parallax-eval file's grid (held-out photographs), by the file's path."""
    totals = {}
    online = result["summary"]["distance_error"].get("total")
    if online is not None:
        totals["online"] = float(online)
    for relative, evaluation in sorted(result.get("evals", {}).items()):
        total = (evaluation.get("distance") or {}).get("by_range", {}).get("total")
        if total is not None:
            totals[relative] = float(total)
    return totals


def _format_totals(totals: dict[str, float]) -> str:
    return ", ".join(f"{what} {value:.2f}%" for what, value in totals.items())


if __name__ == "__main__":
    main()
