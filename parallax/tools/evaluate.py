"""`parallax-eval <run dir>`: frozen measurements of a trained run (paper §4.2, §6; Tables 2–5).

Learning is switched off (dictionaries, policy and distance learner frozen). The robot is shown
held-out textures (photographs never used in training) at every distance of the grid — and,
beyond the paper, at distances between the grid points — and we measure:

- eye-movement MAE per lateral position, |q_p − α*| at the last iteration of each trial, with the
  greedy policy (argmax) and with the sampled policy;
- the distance error per range 3–4.9, 5–6.9, 7–10 m and total (Tables 4–5), from s of the
  greedy policy.

``--split train`` shows the photographs the eye learnt on instead, to tell how much of the
held-out error is the eye's generalisation. Trials start as the run's last training
presentations did (pan 0 as in the paper, or a random pan with ``env.initial_pan_jitter_deg``);
``--start-jitter on|off`` chooses.

Writes `eval.json` and figures (`eval_mae_per_position.png`, `eval_error_vs_distance.png`,
`mae_curves.png`) into the run directory (or --out), holding that folder's lock
(:mod:`parallax.run_folder`) from the start: a folder another process is writing (a run still
training) is refused with one line, and a refused evaluation leaves the folder as it was.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from omegaconf import OmegaConf

from parallax import checkpoint
from parallax.config import (
    load_run_config,
    perturbation_start,
    start_jitter_on,
    validate_stimuli,
)
from parallax.envs.settings import SPLITS
from parallax.experiment import Experiment
from parallax.metrics import position_label
from parallax.readouts import READOUTS
from parallax.routes import SWEEP, Route, planned_route
from parallax.run_folder import RunLock, RunLocked, write_atomic
from parallax.tools import plots
from parallax.tools.console import footer, header, progress
from parallax.tools.report.runs import read_metrics
from parallax.writable import folder_problem

#: The settings of the held-out textures that parallax-eval may change.
STIMULI_PREFIX = "env.stimuli."


def grid(start: float, stop: float, step: float) -> list[float]:
    n = int(round((stop - start) / step)) + 1
    return [round(start + i * step, 6) for i in range(n)]


def run_jobs(
    exp: Experiment,
    jobs: list[tuple[float, int]],
    greedy: bool,
    readout: str = "last",
    route: Route = SWEEP,
    bar: Any = None,
) -> dict[str, np.ndarray]:
    """Run one frozen presentation per (distance, texture) job, B robots at a time (with
    ``route``, Experiment.run_presentation's, one robot on the route it plans); ``bar``, a
    progress bar, moves on by each batch's jobs."""
    pans, other_pans, targets, dists, starts, routes = [], {}, [], [], [], []
    B = exp.robots
    for start in range(0, len(jobs), B):
        batch = jobs[start : start + B]
        padded = batch + [batch[-1]] * (B - len(batch))  # idle robots repeat the last job
        for env, (d, tex) in zip(exp.envs, padded):
            env.task.set_next_stimulus(texture_index=tex, distance=d)
        pres = exp.run_presentation(learn=False, greedy=greedy, route=route)
        routes.append(pres.route)
        pans.append(pres.read(READOUTS[readout])[: len(batch)])
        for name, other in READOUTS.items():
            other_pans.setdefault(name, []).append(pres.read(other)[: len(batch)])
        targets.append(pres.targets[: len(batch)])
        dists.append(pres.distances[: len(batch)])
        starts.append(pres.start_pans[: len(batch)])
        if bar is not None:
            bar.update(len(batch))
    return {
        "pans": np.concatenate(pans),
        "pans_by_readout": {name: np.concatenate(v) for name, v in other_pans.items()},
        "targets": np.concatenate(targets),
        "distances": np.concatenate(dists),
        "start_pans": np.concatenate(starts),
        "routes": routes,
    }


def mae_by_start(run: dict[str, np.ndarray]) -> dict[str, float]:
    """Eye MAE of the trials that started short of α* or on it (the paper's start at pan 0 always
    does) and of those that started past it (only a random start can), with the latter's share."""
    err = np.abs(run["pans"] - run["targets"])
    past = (run["start_pans"] - run["targets"]) * np.sign(run["targets"]) > 0
    out = {"share_started_past": float(past.mean())}
    for name, mask in (("started_short", ~past), ("started_past", past)):
        out[name] = float(err[mask].mean()) if mask.any() else float("nan")
    return out


def distance_results(
    learner, pans: np.ndarray, distances: np.ndarray, truths: np.ndarray | None = None
) -> dict:
    """Errors by range and per distance of ``learner`` on the eye-movement vectors ``pans``, and
    the mean absolute error in the learner's metres. ``truths``: what a perfect learner would
    answer (default: the distances; for odometry targets the slip-free walk,
    ``target_source.truths``); the ranges stay those of the panels' distances. The
    vectors are kept ("samples") so that parallax-replay can score other learners on exactly the
    same eye movements."""
    from parallax.distance.metrics import distance_error_by_range

    pred = np.asarray(learner.predict(np.asarray(pans)), dtype=np.float64).reshape(-1)
    at = np.asarray(distances, dtype=np.float64)
    true = at if truths is None else np.asarray(truths, dtype=np.float64).reshape(-1)
    rel = np.abs(pred - true) / true * 100.0
    per_distance = {}
    for d in np.unique(at):
        per_distance[f"{d:.2f}"] = float(rel[at == d].mean())
    return {
        "by_range": distance_error_by_range(pred, true, at=at),
        "mae_m": float(np.abs(pred - true).mean()),
        "trials": int(at.size),
        "per_distance": per_distance,
        # each trial's error, in the samples' order: comparisons pair them photograph by
        # photograph (parallax.tools.report.paired_ablation)
        "errors": rel.tolist(),
        "samples": {"pans": np.asarray(pans).tolist(), "distances": at.tolist()},
    }


def route_results(planner, pans: np.ndarray, distances: np.ndarray, trial_length: int) -> dict:
    """Where a planning robot (movement.route=planned) would go and what it would estimate for
    each presentation whose full vector s is a row of ``pans``, seeing only the pans of the
    positions it visits (parallax.tools.analysis.movement: the planner on sweeps' eyes)."""
    routes, estimates = [], []
    for s in np.asarray(pans, dtype=np.float64):
        visited, estimate = planner.plan(s)
        routes.append(visited)
        estimates.append(estimate)
    return route_summary(planner, routes, estimates, distances, trial_length)


def route_summary(
    planner, routes: list[list[int]], estimates, distances: np.ndarray, trial_length: int
) -> dict:
    """Distance error, eye movements and lateral travel of planned routes (indices into L)."""
    from parallax.distance.metrics import distance_error_by_range

    lateral_cm = [100.0 * l for l in planner.lateral_positions]
    distances = np.asarray(distances, dtype=np.float64)
    trials = np.array([len(v) for v in routes], dtype=np.float64)
    farthest = np.array([max(lateral_cm[k] for k in v) for v in routes])
    return {
        "price_per_trial": planner.price_per_trial,
        "price_per_cm": planner.price_per_cm,
        "by_range": distance_error_by_range(np.asarray(estimates, dtype=np.float64), distances),
        "presentations": int(distances.size),
        "eye_movements": float(trials.mean() * trial_length),
        "travel_cm": float(2.0 * farthest.mean()),
        "trials_by_distance": {
            f"{d:.2f}": float(trials[distances == d].mean()) for d in np.unique(distances)
        },
        "farthest_cm_by_distance": {
            f"{d:.2f}": float(farthest[distances == d].mean()) for d in np.unique(distances)
        },
        "routes": [list(map(int, v)) for v in routes],
    }


def evaluate(
    run_dir: str | Path,
    textures: int = 1,
    distances: list[float] | None = None,
    between: list[float] | None = None,
    perturbation: str = "auto",
    out: str | Path | None = None,
    checkpoint_name: str = checkpoint.CHECKPOINT_NAME,
    device: str | None = None,
    readout: str | None = None,
    start_jitter: str = "auto",
    robots: int | None = None,
    stimuli: Sequence[str] = (),
    sampled: bool = True,
    split: str = "heldout",
) -> dict:
    """Frozen measurements of the checkpoint ``checkpoint_name`` of ``run_dir`` (module
    docstring). ``robots``: how many frozen robots run the trials in lockstep (default: the
    run's env.robots). Nothing learns, so when trials start from pan 0 the greedy eye's trials,
    and the distance errors made from them, do not depend on it; the sampled policy's draws, and
    jittered start pans, come in another order. Robots that the run did not train start their
    worlds' random streams from the run's seed. ``stimuli``: ``env.stimuli.KEY=VALUE`` settings
    for the held-out textures (e.g. ``env.stimuli.source=procedural``). ``sampled``: also run
    every trial with the sampled policy (its MAE only). ``split``: the textures' split, heldout
    (the paper's measure on unseen photographs) or train (the photographs the eye learnt on, to
    tell the eye's generalisation from its learning)."""
    if robots is not None and robots < 1:
        raise ValueError(f"--robots must be at least 1, got {robots}")
    if start_jitter not in ("auto", "on", "off"):
        raise ValueError(f"--start-jitter must be auto, on or off, got {start_jitter!r}")
    if split not in SPLITS:
        raise ValueError(f"--split must be one of {', '.join(SPLITS)}, got {split!r}")
    if readout is not None and readout not in READOUTS:
        raise ValueError(f"--readout must be one of {', '.join(READOUTS)}, got {readout!r}")
    run_dir = Path(run_dir)
    out_dir = Path(out) if out else run_dir
    cfg = load_run_config(run_dir)
    problem = folder_problem(out_dir)
    if problem:  # before the trials, which take minutes
        where = f"--out {out}" if out else str(run_dir)
        raise ValueError(f"{where}: {problem}; choose another folder with --out DIR")
    # by default, s as the run's distance learner saw it
    readout = readout or str(cfg.train.distance_readout)
    state = read_checkpoint(run_dir, cfg, checkpoint_name, device)
    ckpt_path = run_dir / checkpoint_name
    for item in stimuli:
        key, sep, value = item.partition("=")
        if not sep or not key.startswith(STIMULI_PREFIX) or key == f"{STIMULI_PREFIX}split":
            raise ValueError(
                f"{item!r}: only {STIMULI_PREFIX}KEY=VALUE settings of the held-out textures may "
                "be given (the split: --split)"
            )
        if key[len(STIMULI_PREFIX) :] not in cfg.env.stimuli:
            raise ValueError(f"{item!r}: {key} is not a stimulus setting")
        OmegaConf.update(cfg, key, yaml.safe_load(value) if value else None)
    if stimuli:
        validate_stimuli(cfg)
    trained_robots = int(cfg.env.robots)
    robots = trained_robots if robots is None else int(robots)
    if robots != trained_robots and (
        cfg.movement.route == "planned" or cfg.distance.targets == "odometry"
    ):
        raise ValueError(
            f"--robots {robots}: a run that plans its route or walks is evaluated with its own "
            f"env.robots={trained_robots}"
        )
    cfg.env.robots = robots
    exp, perturbed, jittered = frozen_experiment(
        cfg, state, ckpt_path, split, perturbation, start_jitter, trained_robots
    )
    try:
        if not exp.distance.is_ready:
            print(
                "[parallax-eval] the distance learner never trained (queue not full): "
                "distance errors are left out",
                file=sys.stderr,
            )
        n_tex = exp.envs[0].task.num_textures
        if textures < 1 or textures > n_tex:
            raise ValueError(
                f"--textures must be between 1 and {n_tex} (held-out textures), got {textures}"
            )
        distances = distances or grid(3.0, 10.0, 0.1)
        jobs = [
            (d, (i * textures + k) % n_tex)
            for i, d in enumerate(distances)
            for k in range(textures)
        ]
        labels = [position_label(l) for l in exp.lateral_positions]
        modes = (("greedy", True), ("sampled", False)) if sampled else (("greedy", True),)
        planning = exp.planner is not None and exp.planner.is_ready
        trials = len(jobs) * (len(modes) + planning) + len(between or [])
        header(
            "parallax-eval",
            f"frozen trials of {ckpt_path.resolve()}",
            presentations=int(state["presentation"]),
            perturbed="yes (§5's rotation and blur)" if perturbed else "no",
            photographs=f"{split} split, {textures} per distance",
            trials=f"{trials} ({len(distances)} distances, {', '.join(m for m, _ in modes)}"
            + (f", {len(between)} between grid points" if between else "")
            + (", the planned route" if planning else "")
            + f"; {robots} robot{'s' * (robots > 1)} at a time)",
            output=out_dir.resolve(),
        )
        bar = progress(total=trials, desc="trials", unit="trial")
        result: dict = {
            # absolute, so that the analyses find the run from any working directory
            "run_dir": str(run_dir.resolve()),
            "checkpoint": checkpoint_name,
            "presentations": int(state["presentation"]),
            "readout": readout,
            "perturbed": perturbed,
            "start_jitter": jittered,
            "textures_per_distance": textures,
            "robots": robots,
            "stimuli": {
                **OmegaConf.to_container(cfg.env.stimuli, resolve=True),
                "split": split,
            },
            "stimuli_overrides": list(stimuli),
            "lateral_positions_cm": labels,
            "mae_per_position": {},
            "mae": {},
        }
        runs = {}
        # the worlds' random streams (textures aside: forced; the jittered start pans) as the
        # checkpoint left them, for the planned routes to start from as the sweeps did
        start_streams = [env.task.random_state() for env in exp.envs]
        for mode, greedy in modes:
            runs[mode] = run = run_jobs(exp, jobs, greedy, readout, bar=bar)
            err = np.abs(run["pans"] - run["targets"])
            result["mae_per_position"][mode] = {
                k: float(v) for k, v in zip(labels, err.mean(axis=0))
            }
            result["mae"][mode] = float(err.mean())
            result.setdefault("mae_by_start", {})[mode] = mae_by_start(run)
        between_run = None
        if between:
            between_jobs = [(d, i % n_tex) for i, d in enumerate(between)]
            between_run = run_jobs(exp, between_jobs, True, readout, bar=bar)
        # The greedy eye's vectors s, kept whether or not this run's learner is ready, so that
        # parallax-replay can score other distance learners on exactly these eye movements.
        result["greedy_samples"] = {
            "grid": {
                "pans": runs["greedy"]["pans"].tolist(),
                "distances": runs["greedy"]["distances"].tolist(),
            }
        }
        if between_run is not None:
            result["greedy_samples"]["between"] = {
                "pans": between_run["pans"].tolist(),
                "distances": between_run["distances"].tolist(),
            }
        # and s read out both ways, so that a replay may also change train.distance_readout
        result["greedy_samples_by_readout"] = {
            name: {
                part: {"pans": done["pans_by_readout"][name].tolist()}
                for part, done in (("grid", runs["greedy"]), ("between", between_run))
                if done is not None
            }
            for name in READOUTS
        }
        curves = {}
        if planning:
            # the planning robot's own routes, greedy, on the grid's presentations
            for env, stream in zip(exp.envs, start_streams, strict=True):
                env.task.set_random_state(stream)
            route = planned_route(exp.planner, READOUTS[readout])
            routed = run_jobs(exp, jobs, True, readout, route=route, bar=bar)
            estimates = [
                exp.planner.estimate(v, s[v]) for v, s in zip(routed["routes"], routed["pans"])
            ]
            result["route"] = route_summary(
                exp.planner, routed["routes"], estimates, routed["distances"], exp.trial_length
            )
        if exp.distance.is_ready:
            grid_distances = runs["greedy"]["distances"]
            result["distance"] = distance_results(
                exp.distance,
                runs["greedy"]["pans"],
                grid_distances,
                exp.distance.target_source.truths(grid_distances, exp.parts),
            )
            pd = result["distance"]["per_distance"]
            curves["grid (held-out textures)"] = ([float(k) for k in pd], list(pd.values()))
            if "sampled" in runs:
                # the eye as it trains (the learning policy's draws): with --split train, the
                # paper's probable scoring of Tables 4–5 on the grid
                result["distance_sampled"] = distance_results(
                    exp.distance,
                    runs["sampled"]["pans"],
                    runs["sampled"]["distances"],
                    exp.distance.target_source.truths(runs["sampled"]["distances"], exp.parts),
                )
            if between_run is not None:
                result["distance_between_grid"] = distance_results(
                    exp.distance,
                    between_run["pans"],
                    between_run["distances"],
                    exp.distance.target_source.truths(between_run["distances"], exp.parts),
                )
                pb = result["distance_between_grid"]["per_distance"]
                curves["between grid points"] = ([float(k) for k in pb], list(pb.values()))
        bar.close()
    finally:
        exp.close()

    out_dir.mkdir(parents=True, exist_ok=True)
    plots.mae_per_position(result["mae_per_position"], out_dir / "eval_mae_per_position.png")
    if curves:
        plots.error_vs_distance(curves, out_dir / "eval_error_vs_distance.png")
    records = read_metrics(run_dir)  # plain or compacted (parallax.tools.report.compact)
    if records:
        first = next((i for i, r in enumerate(records) if r.get("perturbed")), None)
        switch = None if first is None else (records[first - 1]["steps"] if first else 0)
        plots.mae_curves(records, out_dir / "mae_curves.png", perturbation_at=switch)
    write_atomic(out_dir / "eval.json", json.dumps(result, indent=2) + "\n")
    written = ["eval.json", "eval_mae_per_position.png"]
    written += ["eval_error_vs_distance.png"] * bool(curves) + ["mae_curves.png"] * bool(records)
    footer("parallax-eval", written, out_dir)
    return result


def read_checkpoint(
    run_dir: Path, cfg, checkpoint_name: str = checkpoint.CHECKPOINT_NAME, device: str | None = None
) -> dict:
    """The checkpoint ``checkpoint_name`` of ``run_dir``, checked against its config ``cfg``
    (:func:`parallax.config.load_run_config`), whose device it sets to ``device`` (default: the
    run's) and whose torch threads it applies. Errors name what to do instead."""
    if device is not None:  # e.g. a run trained on a GPU, evaluated on a machine without one
        if device != "cpu" and not (device == "cuda" or device.startswith("cuda:")):
            raise ValueError(f"--device must be cpu or cuda, got {device!r}")
        cfg.device = device
    if str(cfg.device).startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(
            f"the run was trained with device={cfg.device} and torch sees no CUDA device here; "
            "pass --device cpu"
        )
    if int(cfg.train.threads) > 0:
        # as in training: the matrices are small, and extra intra-op threads contend for the
        # cores the world and the coder's helper threads use (docs/performance.md)
        torch.set_num_threads(int(cfg.train.threads))
    ckpt_path = Path(run_dir) / checkpoint_name
    if not ckpt_path.is_file():
        raise FileNotFoundError(f"{run_dir} has no {checkpoint_name}: nothing to evaluate")
    try:
        return checkpoint.read(ckpt_path, config=cfg)
    except checkpoint.CheckpointError as exc:
        raise ValueError(f"{exc}; {_other_checkpoint(Path(run_dir), checkpoint_name)}") from None


def frozen_experiment(
    cfg,
    state: dict,
    ckpt_path: Path,
    split: str = "heldout",
    perturbation: str = "auto",
    start_jitter: str = "auto",
    trained_robots: int | None = None,
) -> tuple[Experiment, bool, bool]:
    """The run of ``cfg`` with the learnt state of the checkpoint ``state`` (read from
    ``ckpt_path``) on the final list of its curriculum, on the photographs of ``split``; the
    perturbation and the start jitter ``auto`` (as at the end of training), ``on`` or ``off``.
    Robots beyond the ``trained_robots`` (default: cfg.env.robots) start their worlds' random
    streams from the run's seed. Returns the experiment, whether it is perturbed and whether
    its trials start from a jittered pan."""
    exp = Experiment(cfg, stimuli_split=split)
    try:
        learnt = state["experiment"]
        if trained_robots is not None and int(cfg.env.robots) != trained_robots:
            # the checkpoint holds one stream per trained robot; these robots keep their own
            learnt = {**learnt, "env_random": [env.task.random_state() for env in exp.envs]}
        try:
            exp.load_state_dict(learnt)
        except (KeyError, RuntimeError, TypeError, ValueError, IndexError) as exc:
            # written by another version of parallax or another experiment: its parts do not fit
            raise ValueError(
                f"{ckpt_path} does not fit this run's models ({checkpoint.describe(exc)}); "
                f"{_other_checkpoint(ckpt_path.parent, ckpt_path.name)}"
            ) from None
        exp.set_stage(len(exp.stages) - 1)
        start = perturbation_start(cfg)
        # Perturbed once a presentation ran after the switch (a checkpoint taken at the switch
        # holds the learnt state from before it).
        was_perturbed = start is not None and state["presentation"] > start
        perturbed = {"auto": was_perturbed, "on": True, "off": False}[perturbation]
        exp.set_perturbation(perturbed)
        # auto: trials start as the checkpoint's last training presentations did (jittered or 0)
        jittered = {
            "auto": start_jitter_on(cfg, max(0, int(state["presentation"]) - 1)),
            "on": True,
            "off": False,
        }[start_jitter]
        exp.set_start_jitter(jittered)
    except BaseException:
        exp.close()
        raise
    return exp, perturbed, jittered


def _other_checkpoint(run_dir: Path, name: str) -> str:
    """What to do when the checkpoint ``name`` of ``run_dir`` cannot be evaluated."""
    if name == checkpoint.CHECKPOINT_NAME and (run_dir / checkpoint.PREVIOUS_NAME).is_file():
        return f"evaluate the one before with --checkpoint {checkpoint.PREVIOUS_NAME}"
    return "evaluate another checkpoint with --checkpoint NAME, or train the run again"


def format_eval(result: dict) -> str:
    lines = (
        []
        if result.get("readout", "last") == "last"
        else [
            f"readout: {result['readout']} (each trial's pan where the coder's reward was highest)"
        ]
    )
    modes = list(result["mae_per_position"])
    lines.append(f"{'position (cm)':>14}" + "".join(f" {m + ' MAE':>12}" for m in modes))
    for k in result["lateral_positions_cm"]:
        lines.append(
            f"{k:>14}" + "".join(f" {result['mae_per_position'][m][k]:>12.3f}" for m in modes)
        )
    if result.get("start_jitter") and "mae_by_start" in result:
        for mode, m in result["mae_by_start"].items():
            lines.append(
                f"{mode} MAE of trials that started short of α* {_shown(m['started_short'])}, "
                f"past it {_shown(m['started_past'])} "
                f"({100 * m['share_started_past']:.0f} % of trials)"
            )
    if "distance" in result:
        lines.append("distance error (%): " + _ranges(result["distance"]["by_range"]))
    if "distance_sampled" in result:
        lines.append(
            "distance error of the sampled policy's eye (%): "
            + _ranges(result["distance_sampled"]["by_range"])
        )
    if "route" in result:
        route = result["route"]
        lines.append(
            f"planned route: distance error {route['by_range']['total']:.2f} % with "
            f"{route['eye_movements']:.0f} eye movements and {route['travel_cm']:.0f} cm of "
            "travel per presentation"
        )
    if "distance_between_grid" in result:
        lines.append(
            "between grid points (%): " + _ranges(result["distance_between_grid"]["by_range"])
        )
    return "\n".join(lines)


def _shown(degrees: float | None) -> str:
    """An MAE in degrees, or – where no trial had it (NaN, null)."""
    return "–" if degrees is None or degrees != degrees else f"{degrees:.3f}°"


def _ranges(by_range: dict) -> str:
    """``3-4.9 m: 1.23  …  total: 1.00``; a range no distance fell in says so."""
    return "  ".join(
        f"{k}{'' if k == 'total' else ' m'}: " + ("no panel" if v is None or v != v else f"{v:.2f}")
        for k, v in by_range.items()
    )


def build_parser() -> argparse.ArgumentParser:
    """parallax-eval's command line: RUN, then env.stimuli.KEY=VALUE settings and options in any
    order (a setting must not follow --distances or --between, which take every number after
    them)."""
    parser = argparse.ArgumentParser(prog="parallax-eval", description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", help="a run directory written by parallax-train")
    parser.add_argument(
        "stimuli",
        nargs="*",
        metavar="env.stimuli.KEY=VALUE",
        help="held-out textures of another kind, e.g. env.stimuli.source=procedural "
        "env.stimuli.kind=pink_noise, or env.stimuli.dir=FOLDER (default: the run's)",
    )
    parser.add_argument(
        "--textures", type=int, default=1, help="held-out textures per distance (default 1)"
    )
    parser.add_argument(
        "--distances",
        type=float,
        nargs="+",
        default=None,
        help="distances in metres (default: the grid 3.0, 3.1, …, 10.0)",
    )
    parser.add_argument(
        "--between",
        type=_distance_or_none,
        nargs="*",
        default=[3.05, 4.47, 5.55, 7.33, 8.81, 9.95],
        help="extra distances between grid points (default: a few; none to skip)",
    )
    parser.add_argument(
        "--perturbation",
        choices=["auto", "on", "off"],
        default="auto",
        help="auto: as at the end of training",
    )
    parser.add_argument(
        "--start-jitter",
        choices=["auto", "on", "off"],
        default="auto",
        help="trials start from the run's env.initial_pan_jitter_deg (on) or from pan 0 "
        "as in the paper (off); auto: as at the end of training",
    )
    parser.add_argument(
        "--out", default=None, help="where to write eval.json and figures (default: run dir)"
    )
    parser.add_argument(
        "--checkpoint",
        default=checkpoint.CHECKPOINT_NAME,
        help=f"checkpoint file in the run dir (default {checkpoint.CHECKPOINT_NAME}; "
        f"{checkpoint.BEFORE_PERTURBATION_NAME} for the state before §5's perturbation, "
        f"{checkpoint.PREVIOUS_NAME} for the one written before the latest)",
    )
    parser.add_argument(
        "--device", default=None, help="cpu or cuda (default: the device the run was trained on)"
    )
    parser.add_argument(
        "--readout",
        default=None,
        help="last: each trial's last pan, the paper's q_p; best_reward (beyond the "
        "paper): the pan where the coder's reward was highest (default: the "
        "run's train.distance_readout)",
    )
    parser.add_argument(
        "--robots",
        type=int,
        default=None,
        help="frozen robots that run the trials in lockstep, for speed; from pan 0, the greedy "
        "eye and the distance errors do not depend on it (default: the run's env.robots)",
    )
    parser.add_argument(
        "--split",
        choices=SPLITS,
        default="heldout",
        help="the photographs: heldout (default), or train, those the eye learnt on",
    )
    parser.add_argument(
        "--greedy-only",
        action="store_true",
        help="leave out the sampled policy's trials (half the time; no sampled MAE)",
    )
    return parser


def _distance_or_none(text: str) -> float | None:
    """A distance of --between, or None for ``none``."""
    if text.lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a distance in metres nor none: {text!r}") from None


def main(argv: list[str] | None = None) -> None:
    # intermixed: the positional settings may come after options such as --out
    parser = build_parser()
    args = parser.parse_intermixed_args(argv)
    if None in args.between:  # --between none
        if len(args.between) > 1:
            parser.error("--between: none stands alone, without distances")
        args.between = []
    # the folder written into has one writer (parallax.run_folder), locked before anything is
    # written; one that cannot be written is named by evaluate()
    out_dir = Path(args.out or args.run_dir)
    lock = RunLock(out_dir, program="parallax-eval") if folder_problem(out_dir) is None else None
    try:
        if lock is not None:
            lock.acquire()
    except RunLocked as exc:
        remedy = "wait for it to end, or write elsewhere with --out DIR"
        print(f"parallax-eval: error: {exc}; {remedy}", file=sys.stderr)
        sys.exit(2)
    try:
        result = evaluate(
            args.run_dir,
            textures=args.textures,
            distances=args.distances,
            between=args.between,
            perturbation=args.perturbation,
            out=args.out,
            checkpoint_name=args.checkpoint,
            device=args.device,
            readout=args.readout,
            start_jitter=args.start_jitter,
            robots=args.robots,
            stimuli=args.stimuli,
            sampled=not args.greedy_only,
            split=args.split,
        )
    except (FileNotFoundError, ValueError) as exc:
        if lock is not None:
            lock.release(restore=True)  # refused: the folder as it was
        print(f"parallax-eval: error: {exc}", file=sys.stderr)
        sys.exit(2)
    finally:
        if lock is not None:
            lock.release()
    print(format_eval(result))


if __name__ == "__main__":
    main()
