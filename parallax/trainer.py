"""The trainer: presentations, metrics, TensorBoard, progress, checkpoints and the summary.

Paper §3.2 (the loop, via `parallax.experiment`), §4.2 (eye-movement MAE, eq. 16, Tables 2–3),
§5 (perturbations switched on mid-run, training continuing) and §6 (distance error per range,
Tables 4–5). Everything a run writes lives in its run directory:

    config.yaml       the composed config, resolved (Hydra's own record is in .hydra/)
    tb/               TensorBoard events
    metrics.jsonl     one line per presentation (deterministic: no wall-clock values), with the
                      eye-movement vectors s the distance learner saw (for parallax-replay)
    checkpoint.pt     the latest checkpoint (atomic), and checkpoint_previous.pt the one before
    summary.json      the final summary (and the one before the perturbation)

After each presentation :mod:`parallax.health` reads its record: a diverging critic is named
once, and numbers that stopped being finite hold back the checkpoints and, in the end, stop the
run with :class:`parallax.health.Diverged`.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from parallax import checkpoint
from parallax.config import (
    READOUT_PANS,
    RUN_CONFIG_NAME,
    distance_readout,
    growth_start,
    perturbation_start,
    start_jitter_on,
)
from parallax.experiment import Experiment, Presentation
from parallax.health import Diverged, Health
from parallax.metrics import DistanceErrorTracker, EyeMovementTracker, learn_online, position_label
from parallax.record import PresentationRecord, Route, Walks


class Trainer:
    def __init__(self, cfg: DictConfig, run_dir: str | Path):
        self.cfg = cfg
        self.run_dir = Path(run_dir)
        if int(cfg.train.threads) > 0:
            torch.set_num_threads(int(cfg.train.threads))
        self.exp = Experiment(cfg)
        self.eye = EyeMovementTracker(
            self.exp.lateral_positions, window=int(cfg.metrics.mae_window)
        )
        self.dist = DistanceErrorTracker(window=int(cfg.metrics.distance_window))
        # beyond the paper (§7): the planned routes' estimates, apart from the sweeps' network
        self.route_dist = DistanceErrorTracker(window=int(cfg.metrics.distance_window))
        self.presentation = 0
        self.steps = 0
        self.wall_time = 0.0
        self.before_perturbation: dict | None = None
        self.last_distance_stats: dict[str, float] = {}
        self.perturbation_start = perturbation_start(cfg)
        self.growth_start = growth_start(cfg)
        self.health = Health(cfg.train.critic_scale_warning, cfg.train.stop_after_non_finite)
        self.distance_fitted = False  # whether the distance learner fitted in this presentation
        # A run resumed from checkpoint_previous.pt keeps it as the previous one: the latest
        # checkpoint, which it was resumed instead of, may be the damaged one.
        self.keep_latest = True
        # the last checkpoint written or resumed from, and its presentation
        self.saved: tuple[Path, int] | None = None

    # --- paths -----------------------------------------------------------------------------
    @property
    def checkpoint_path(self) -> Path:
        return self.run_dir / checkpoint.CHECKPOINT_NAME

    @property
    def previous_path(self) -> Path:
        return self.run_dir / checkpoint.PREVIOUS_NAME

    @property
    def resume_path(self) -> Path:
        """The checkpoint a resumed run continues from (train.resume_from)."""
        latest = str(self.cfg.train.resume_from) == "latest"
        return self.checkpoint_path if latest else self.previous_path

    @property
    def metrics_path(self) -> Path:
        return self.run_dir / "metrics.jsonl"

    @property
    def summary_path(self) -> Path:
        return self.run_dir / "summary.json"

    # --- checkpoints -----------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            "presentation": self.presentation,
            "steps": self.steps,
            "wall_time": self.wall_time,
            "experiment": self.exp.state_dict(),
            "eye": self.eye.state_dict(),
            "dist": self.dist.state_dict(),
            "before_perturbation": self.before_perturbation,
            "last_distance_stats": self.last_distance_stats,
            "global_rng": checkpoint.global_rng_state(),
            **({"route_dist": self.route_dist.state_dict()} if self.exp.planner else {}),
            # the settings it was trained with, so that it is never resumed or evaluated as
            # another run's (checkpoint.read)
            "config": OmegaConf.to_container(self.cfg, resolve=True),
            "health": self.health.state_dict(),
        }

    def save(self) -> None:
        previous = self.previous_path if self.keep_latest else None
        checkpoint.save_atomic(self.state_dict(), self.checkpoint_path, previous=previous)
        self.keep_latest, self.saved = True, (self.checkpoint_path, self.presentation)

    def restore(self) -> bool:
        """Continue from the checkpoint of train.resume_from, if there is one; drop log lines
        written after it. A checkpoint that cannot be used raises checkpoint.CheckpointError."""
        path = self.resume_path
        if not path.exists():
            return False
        # map_location=cpu: load_state_dict copies onto the run's device
        state = checkpoint.read(path, config=self.cfg, map_location="cpu")
        try:
            self.exp.load_state_dict(state["experiment"])
            self.eye.load_state_dict(state["eye"])
            self.dist.load_state_dict(state["dist"])
            if self.exp.planner is not None:
                self.route_dist.load_state_dict(state["route_dist"])
            if state.get("health") is not None:
                self.health.load_state_dict(state["health"])
        except (KeyError, RuntimeError, TypeError, ValueError, IndexError) as exc:
            # written by another version of parallax or another experiment: its parts do not fit
            raise checkpoint.CheckpointError(
                path, f"does not fit this run's models ({checkpoint.describe(exc)})"
            ) from None
        self.presentation, self.steps = int(state["presentation"]), int(state["steps"])
        self.wall_time = float(state["wall_time"])
        self.before_perturbation = state["before_perturbation"]
        self.last_distance_stats = state["last_distance_stats"]
        checkpoint.set_global_rng_state(state["global_rng"])
        self.keep_latest, self.saved = path == self.checkpoint_path, (path, self.presentation)
        if self.metrics_path.exists():
            kept = [
                line
                for line in self.metrics_path.read_text().splitlines()
                if _presentation_of(line) <= self.presentation
            ]
            self.metrics_path.write_text("".join(line + "\n" for line in kept))
        return True

    # --- one presentation ------------------------------------------------------------------
    def _learn_distance(self, pres: Presentation) -> Walks | None:
        """The distance learner's step after a presentation; with odometry targets, the walks
        first. Returns what the walks were, for the log (None without)."""
        pans = getattr(pres, READOUT_PANS[distance_readout(self.cfg)])
        walked = None
        if self.exp.walks:
            counted, reach = self.exp.walk()
            source = self.exp.distance.target_source
            truths = [source.truth(d, r) for d, r in zip(pres.distances, reach)]
            stride, nominal = self.exp.walkers[0].true_stride_m, source.nominal_stride_m
            walked = Walks(
                walk_strides=counted,
                reach_strides=reach,
                # what the robot believes it walked against what it walked, in %
                odometry_error_pct=[
                    None if n is None else 100.0 * (n * nominal / (r * stride) - 1.0)
                    for n, r in zip(counted, reach)
                ],
                true_stride_m=stride,
            )
            stats = learn_online(
                self.exp.distance, self.dist, pans, truths, counted, distances=pres.distances
            )
        else:
            stats = learn_online(self.exp.distance, self.dist, pans, pres.distances)
        if stats:
            self.last_distance_stats = stats
        self.distance_fitted = bool(stats.get("trained"))
        return walked

    def _route_record(self, pres: Presentation, key: str, learnt_distance: bool) -> Route:
        """A planned route's log entries, and its estimate scored online (a sweep's is the
        network's, in ``distance_error``)."""
        lateral_cm = [100.0 * l for l in pres.lateral_positions]
        visited = list(range(len(lateral_cm))) if pres.route is None else pres.route
        estimate = None
        if pres.route is not None and learnt_distance:
            pans = getattr(pres, key)[0]
            estimate = self.exp.planner.estimate(pres.route, pans[pres.route])
            self.route_dist.record(estimate, float(pres.distances[0]))
        return Route(
            route=pres.route,
            trials=len(visited),
            travel_cm=2.0 * max(lateral_cm[k] for k in visited),
            route_distance_error=self.route_dist.by_range(),
            estimate=estimate,
        )

    def _maybe_advance_stage(self) -> None:
        if self.exp.on_final_list:
            return
        cur = self.cfg.curriculum
        stage = [position_label(l) for l in self.exp.stages[self.exp.stage]]
        enough = all(len(self.eye.per_position[k]) >= int(cur.min_trials) for k in stage)
        mae = self.eye.mae_per_position()
        if enough and all(mae[k] <= float(cur.advance_below_deg) for k in stage):
            self.exp.set_stage(self.exp.stage + 1)

    def step_presentation(self, keep_view: bool) -> tuple[Presentation, PresentationRecord]:
        # the random start pan only during train.start_jitter_presentations, then pan 0 as in the
        # paper; derived from the count, so a resumed run switches at the same presentation
        jittered = start_jitter_on(self.cfg, self.presentation)
        self.exp.set_start_jitter(jittered)
        key = READOUT_PANS[distance_readout(self.cfg)]
        sweeps = self.exp.sweeps(float(self.cfg.movement.explore))
        route = None if sweeps else self.exp.planned_route(key)
        pres = self.exp.run_presentation(learn=True, greedy=False, keep_view=keep_view, route=route)
        visited = range(len(pres.labels)) if pres.route is None else pres.route
        for b in range(self.exp.robots):
            for p in visited:
                self.eye.record(pres.labels[p], pres.pans[b, p], pres.targets[b, p])
        learnt_distance = self.exp.on_final_list
        walked, moved = None, None
        self.distance_fitted = False
        if learnt_distance and pres.route is None:
            walked = self._learn_distance(pres)
            if self.exp.planner is not None:  # a full sweep: the planner's queue learns it
                self.exp.planner.observe(getattr(pres, key)[0], float(pres.distances[0]))
        if self.exp.planner is not None:
            moved = self._route_record(pres, key, learnt_distance)
        ran_perturbed = self.perturbed  # before the count moves on: how this presentation ran
        self.presentation += 1
        self.steps += pres.steps
        self._maybe_advance_stage()
        record = PresentationRecord(
            presentation=self.presentation,
            steps=self.steps,
            stage=self.exp.stage,
            perturbed=ran_perturbed,
            reward=pres.reward,
            errors=pres.errors,
            policy_stats=pres.policy_stats,
            mae=self.eye.mae(),
            mae_per_position=self.eye.mae_per_position(),
            mae_recent=self.eye.recent_mae(int(self.cfg.metrics.summary_trials)),
            mae_recent_per_position={
                k: v["mean"]
                for k, v in self.eye.last_trials(int(self.cfg.metrics.summary_trials)).items()
            },
            distance_error=self.dist.by_range(),
            pans=pres.pans.tolist(),
            distances=pres.distances.tolist(),
            best_pans=pres.best_pans.tolist(),
            start_pans=pres.start_pans.tolist(),
            start_jitter=jittered,
            learnt_distance=learnt_distance,
            walks=walked,
            route=moved,
            distance_stats=dict(self.last_distance_stats),
        )
        return pres, record

    @property
    def grown(self) -> bool:
        return self.growth_start is not None and self.presentation >= self.growth_start

    @property
    def perturbed(self) -> bool:
        return self.perturbation_start is not None and self.presentation >= self.perturbation_start

    # --- summary ---------------------------------------------------------------------------
    def metrics_summary(self) -> dict:
        return {
            "presentations": self.presentation,
            "trials": self.eye.trials,
            "mae": self.eye.mae(),
            "mae_per_position": self.eye.mae_per_position(),
            "last_trials": self.eye.last_trials(int(self.cfg.metrics.summary_trials)),
            "distance_error": self.dist.by_range(),
            **({"route_distance_error": self.route_dist.by_range()} if self.exp.planner else {}),
        }

    def summary(self) -> dict:
        return {
            "curriculum": self.cfg.curriculum.name,
            "lateral_positions_cm": [position_label(l) for l in self.exp.lateral_positions],
            "seed": int(self.cfg.seed),
            "robots": self.exp.robots,
            "steps": self.steps,
            **self.metrics_summary(),
            "before_perturbation": self.before_perturbation,
            "timing": {
                "wall_time_s": self.wall_time,
                "steps_per_second": self.steps * self.exp.robots / max(self.wall_time, 1e-9),
            },
        }

    # --- the run ---------------------------------------------------------------------------
    def _log_images(self, writer: SummaryWriter, pres: Presentation) -> None:
        for scale in self.exp.coder.scales:
            grid = np.asarray(self.exp.coder.atom_grid(scale))
            writer.add_image(
                f"coder/atoms_{scale}",
                grid,
                self.steps,
                dataformats="HW" if grid.ndim == 2 else "HWC",
            )
        if pres.last_view is not None:
            writer.add_image("world/I0_beside_It", pres.last_view, self.steps, dataformats="HWC")

    def skipped_updates(self) -> int:
        """The policy's running count of updates it skipped as not finite (0 if it keeps none)."""
        count = getattr(self.exp.policy, "rejected_updates", None)
        return 0 if count is None else int(count)

    def fit(self) -> dict:
        cfg = self.cfg
        total = int(cfg.train.presentations)
        resumed = bool(cfg.resume) and self.restore()
        self.run_dir.mkdir(parents=True, exist_ok=True)
        if not resumed:  # a start from scratch: no lines of an earlier start without a checkpoint
            self.metrics_path.write_text("")
        (self.run_dir / RUN_CONFIG_NAME).write_text(OmegaConf.to_yaml(cfg, resolve=True))
        if self.perturbed:
            self.exp.set_perturbation(True)
        self.exp.set_growth(self.grown)
        self.health.skipped_seen = self.skipped_updates()
        writer = SummaryWriter(str(self.run_dir / "tb"), purge_step=self.steps if resumed else None)
        if not resumed:
            writer.add_text("config", "```yaml\n" + OmegaConf.to_yaml(cfg) + "\n```", 0)
        interactive = sys.stderr.isatty()
        bar = tqdm(
            total=total,
            initial=self.presentation,
            desc="presentations",
            unit="pres",
            disable=not interactive,
            dynamic_ncols=True,
        )
        log_every = max(1, total // 20)
        try:
            with self.metrics_path.open("a") as log:
                while self.presentation < total:
                    if (
                        self.perturbation_start is not None
                        and self.presentation == self.perturbation_start
                    ):
                        self.before_perturbation = self.metrics_summary()
                        # The learnt state just before §5's perturbation, for
                        # parallax-eval --checkpoint.
                        checkpoint.save_atomic(
                            self.state_dict(), self.run_dir / checkpoint.BEFORE_PERTURBATION_NAME
                        )
                        self.exp.set_perturbation(True)
                    if self.presentation == self.growth_start:
                        self.exp.set_growth(True)  # the body's stride grows; the robot's belief not
                    keep_view = (self.presentation + 1) % int(cfg.train.image_every) == 0
                    t0 = time.perf_counter()
                    pres, record = self.step_presentation(keep_view)
                    dt = time.perf_counter() - t0
                    self.wall_time += dt
                    sps = pres.steps * self.exp.robots / dt
                    line = record.to_json()
                    log.write(json.dumps(line) + "\n")
                    log.flush()
                    for tag, value in record.scalars(sps):
                        writer.add_scalar(tag, value, self.steps)
                    skipped = self.skipped_updates()
                    self.health.report(line, skipped, self.distance_fitted, writer, self.steps)
                    if keep_view:
                        self._log_images(writer, pres)
                    dist_total = record.distance_error.get("total")
                    if interactive:
                        bar.set_postfix(
                            steps_s=f"{sps:.0f}",
                            mae=f"{record.mae:.3f}",
                            recent=f"{record.mae_recent:.3f}",
                            dist=f"{dist_total:.2f}%" if dist_total is not None else "-",
                        )
                        bar.update(1)
                    elif self.presentation % log_every == 0 or self.presentation == total:
                        print(
                            f"[parallax] presentation {self.presentation}/{total}  "
                            f"steps/s {sps:.0f}  MAE {record.mae:.3f}° "
                            f"(last {int(cfg.metrics.summary_trials)} trials "
                            f"{record.mae_recent:.3f}°)  distance error "
                            + (f"{dist_total:.2f}%" if dist_total is not None else "-"),
                            flush=True,
                        )
                    if self.health.must_stop:
                        message = self.health.stop_message(self.presentation, self.saved)
                        writer.add_text("health", message, self.steps)
                        raise Diverged(message)
                    # while the numbers are not finite, the last checkpoint stays the last good one
                    holding = not self.health.healthy and self.health.stop_after is not None
                    if not holding and (
                        self.presentation % int(cfg.train.checkpoint_every) == 0
                        or self.presentation == total
                    ):
                        self.save()
        finally:
            bar.close()
            writer.close()
        summary = self.summary()
        self.summary_path.write_text(json.dumps(summary, indent=2) + "\n")
        return summary


def _presentation_of(line: str) -> float:
    """The presentation a metrics.jsonl line belongs to; a line torn by a hard kill counts as
    after any checkpoint, so resuming drops it."""
    try:
        return json.loads(line)["presentation"]
    except (json.JSONDecodeError, KeyError, TypeError):
        return float("inf")


def format_summary(summary: dict) -> str:
    """The final table printed at the end of a run."""
    lines = [
        f"parallax — {summary['curriculum']}, seed {summary['seed']}, "
        f"{summary['presentations']} presentations, {summary['steps']} iterations per robot"
    ]
    lines.append(f"{'position (cm)':>14} {'MAE (window)':>13} {'last-trials mean (var)':>24}")
    for label, mae in summary["mae_per_position"].items():
        lt = summary["last_trials"][label]
        lines.append(f"{label:>14} {mae:>13.3f} {lt['mean']:>15.3f} ({lt['var']:.3f})")
    lines.append(f"{'all':>14} {summary['mae']:>13.3f}")
    if summary["distance_error"]:
        lines.append(
            "distance error (%): "
            + "  ".join(
                f"{k}{'' if k == 'total' else ' m'}: {v:.2f}"
                for k, v in summary["distance_error"].items()
            )
        )
    else:
        lines.append("distance error: not yet (the queue of the distance learner is not full)")
    t = summary["timing"]
    lines.append(f"wall time {t['wall_time_s']:.0f} s, {t['steps_per_second']:.0f} steps/s")
    return "\n".join(lines)
