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
    diverged.json     instead of a summary, for a run stopped as its numbers stopped being finite
    parallax.lock     while a command writes the folder: who (parallax.run_folder, whose lock
                      parallax-train takes before it builds this trainer)

After each presentation :mod:`parallax.health` reads its record: a diverging critic is named
once, and numbers that stopped being finite hold back the checkpoints and, in the end, stop the
run with :class:`parallax.health.Diverged`.
"""

from __future__ import annotations

import functools
import json
import time
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf

from parallax import checkpoint
from parallax.compressed import read_record, record_file, record_forms
from parallax.config import (
    RUN_CONFIG_NAME,
    perturbation_start,
    start_jitter_on,
)
from parallax.experiment import Experiment
from parallax.health import DIVERGED_NAME, Diverged, Health
from parallax.metrics import (
    DistanceErrorTracker,
    EyeMovementTracker,
    finite_or_none,
    position_label,
)
from parallax.panel import montage_picks, panel_frames, pictured_count, watched
from parallax.parts import Parts
from parallax.presentation import Presentation
from parallax.readouts import READOUTS, of_run
from parallax.record import PresentationRecord
from parallax.routes import movement
from parallax.run_folder import remove_leftovers, write_atomic
from parallax.run_log import RunLog, can_write_video
from parallax.watch import Watch

#: The video panel of train.image_every's presentations in TensorBoard: about this many frames
#: (and each trial's end), this wide in pixels; few and small, so that drawing them costs a
#: small share of the presentations between.
PANEL_FRAMES, PANEL_WIDTH = 24, 640

#: The files of a run written through a temporary file and a rename.
_WRITTEN = (
    checkpoint.CHECKPOINT_NAME,
    checkpoint.PREVIOUS_NAME,
    checkpoint.BEFORE_PERTURBATION_NAME,
    "metrics.jsonl",
    "summary.json",
    RUN_CONFIG_NAME,
    DIVERGED_NAME,
)


class Trainer:
    """Trains one run into ``run_dir``: the parts of ``cfg`` (built unless given), the distance
    step of its distance.targets and the movement of its movement.route."""

    def __init__(self, cfg: DictConfig, run_dir: str | Path, parts: Parts | None = None):
        self.cfg = cfg
        self.run_dir = Path(run_dir)
        if int(cfg.train.threads) > 0:
            torch.set_num_threads(int(cfg.train.threads))
        self.exp = Experiment(cfg, parts=parts)
        # where the distance learner's targets come from, and its step after a sweep
        self.targets = self.exp.distance.target_source
        self.readout = of_run(cfg)  # which pan of each trial s holds
        self.movement = movement(cfg, self.exp.parts, self.readout)
        self.eye = EyeMovementTracker(
            self.exp.lateral_positions, window=int(cfg.metrics.mae_window)
        )
        self.dist = DistanceErrorTracker(window=int(cfg.metrics.distance_window))
        self.presentation = 0
        self.steps = 0
        self.wall_time = 0.0
        self.before_perturbation: dict | None = None
        self.last_distance_stats: dict[str, float] = {}
        self.perturbation_start = perturbation_start(cfg)
        self.health = Health(cfg.train.critic_scale_warning, cfg.train.stop_after_non_finite)
        self.distance_fitted = False  # whether the distance learner fitted in this presentation
        # A run resumed from checkpoint_previous.pt keeps it as the previous one: the latest
        # checkpoint, which it was resumed instead of, may be the damaged one.
        self.keep_latest = True
        # the last checkpoint written or resumed from, and its presentation
        self.saved: tuple[Path, int] | None = None
        self.loaded = False  # whether the checkpoint of train.resume_from is loaded

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
            **self.movement.state_dict(),  # a planned route's own distance errors
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
        if not self.load_checkpoint():
            return False
        self._trim_record()
        return True

    def load_checkpoint(self) -> bool:
        """Load the checkpoint of train.resume_from into the run's models and counters, if there
        is one, writing nothing; whether there was. Asked twice, it loads once. A checkpoint that
        cannot be used (:func:`parallax.checkpoint.read`, or whose parts do not fit the models)
        raises checkpoint.CheckpointError."""
        if self.loaded:
            return True
        path = self.resume_path
        if not path.exists():
            return False
        # map_location=cpu: load_state_dict copies onto the run's device. Numbers that are not
        # finite are refused, but in a study of divergence, whose checkpoints may hold them.
        finite = self.cfg.train.stop_after_non_finite is not None
        state = checkpoint.read(path, config=self.cfg, map_location="cpu", finite=finite)
        try:
            self.exp.load_state_dict(state["experiment"])
            self.eye.load_state_dict(state["eye"])
            self.dist.load_state_dict(state["dist"])
            self.movement.load_state_dict(state)
            if state.get("health") is not None:
                self.health.load_state_dict(state["health"])
        except (KeyError, RuntimeError, TypeError, ValueError, IndexError) as exc:
            # written by another version of parallax or another experiment: its parts do not fit
            raise checkpoint.CheckpointError(
                path, f"does not fit this run's models ({checkpoint.describe(exc)})"
            ) from None
        self.presentation, self.steps = int(state["presentation"]), int(state["steps"])
        self.wall_time = float(state["wall_time"])
        # a phase lengthened before the perturbation: its summary is taken again at the new start
        self.before_perturbation = state["before_perturbation"] if self.perturbed else None
        self.last_distance_stats = state["last_distance_stats"]
        checkpoint.set_global_rng_state(state["global_rng"])
        self.keep_latest, self.saved = path == self.checkpoint_path, (path, self.presentation)
        self.loaded = True
        return True

    def _trim_record(self) -> None:
        """metrics.jsonl up to the checkpoint's presentation: the lines written after it, and a
        line torn by a kill in the middle of its write, dropped (atomically: a kill now leaves
        the record as it was)."""
        found = record_file(self.metrics_path)
        if found is None:
            return
        kept = [
            line
            for line in read_record(self.metrics_path).splitlines()
            if _presentation_of(line) <= self.presentation
        ]
        write_atomic(self.metrics_path, "".join(line + "\n" for line in kept))
        # a compacted record goes on as the plain file the log appends to
        if found != self.metrics_path:
            found.unlink()

    # --- one presentation ------------------------------------------------------------------
    def step_presentation(
        self, keep_view: bool, watch: Watch | None = None
    ) -> tuple[Presentation, PresentationRecord]:
        """One presentation on its route (robot 0 watched by ``watch``), the eye's errors, the
        distance step after a sweep of the final list, and the presentation's record."""
        # the random start pan only during train.start_jitter_presentations, then pan 0 as in the
        # paper; derived from the count, so a resumed run switches at the same presentation
        jittered = start_jitter_on(self.cfg, self.presentation)
        self.exp.set_start_jitter(jittered)
        route = self.movement.route()
        around = None if watch is None else watch.around
        pres = self.exp.run_presentation(learn=True, keep_view=keep_view, route=route, watch=around)
        for b in range(self.exp.robots):
            for p in range(len(pres.labels)) if pres.route is None else pres.route:
                self.eye.record(pres.labels[p], pres.pans[b, p], pres.targets[b, p])
        learnt_distance, walked = self.exp.on_final_list, None
        self.distance_fitted = False
        if learnt_distance and pres.route is None:
            pans = pres.read(self.readout)
            parts = self.exp.parts
            stats, walked = self.targets.learn(
                parts.distance, self.dist, pans, pres.distances, parts
            )
            self.last_distance_stats = stats or self.last_distance_stats
            self.distance_fitted = bool(stats.get("trained"))
        moved = self.movement.after(pres, learnt_distance)
        ran_perturbed = self.perturbed  # before the count moves on: how this presentation ran
        self.presentation += 1
        self.steps += pres.steps
        self._maybe_advance_stage()
        summary_trials = int(self.cfg.metrics.summary_trials)
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
            mae_recent=self.eye.recent_mae(summary_trials),
            mae_recent_per_position={
                k: v["mean"] for k, v in self.eye.last_trials(summary_trials).items()
            },
            distance_error=self.dist.by_range(),
            pans=pres.pans.tolist(),
            distances=pres.distances.tolist(),
            readouts={r.key: pres.read(r).tolist() for r in READOUTS.values() if not r.paper},
            start_pans=pres.start_pans.tolist(),
            start_jitter=jittered,
            learnt_distance=learnt_distance,
            walks=walked,
            motion=pres.motion,
            route=moved,
            distance_stats=dict(self.last_distance_stats),
        )
        return pres, record

    def _maybe_advance_stage(self) -> None:
        if self.exp.on_final_list:
            return
        cur = self.cfg.curriculum
        stage = [position_label(l) for l in self.exp.stages[self.exp.stage]]
        enough = all(len(self.eye.per_position[k]) >= int(cur.min_trials) for k in stage)
        mae = self.eye.mae_per_position()
        if enough and all(mae[k] <= float(cur.advance_below_deg) for k in stage):
            self.exp.set_stage(self.exp.stage + 1)

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
            "distance_error_queue": self.exp.distance.queue_error(),
            **self.movement.summary(),
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
    def skipped_updates(self) -> int:
        """The policy's running count of updates it skipped as not finite."""
        return int(self.exp.policy.rejected_updates)

    def fit(self) -> dict:
        """The run, from its checkpoint if it has one, to train.presentations; its summary."""
        total = int(self.cfg.train.presentations)
        resumed = self._start()
        with RunLog(self.run_dir, self.cfg, self.presentation, self.steps, resumed) as log:
            while self.presentation < total:
                self._switch_schedule()
                keep_view = (self.presentation + 1) % int(self.cfg.train.image_every) == 0
                watch = Watch.spread(self.exp.envs[0], PANEL_FRAMES) if keep_view else None
                started = time.perf_counter()
                pres, record = self.step_presentation(keep_view, watch)
                seconds = time.perf_counter() - started
                self.wall_time += seconds
                line = log.write(record, pres.steps * self.exp.robots / seconds)
                skipped, fitted = self.skipped_updates(), self.distance_fitted
                self.health.report(line, skipped, fitted, log.writer, self.steps)
                if keep_view:
                    log.images(self.exp.coder, pres, self.steps)
                    log.panel(self._panel(watch, pres), self.steps)
                if self.health.must_stop:
                    stop = self.health.stop_record(self.presentation, self.saved)
                    # §5's first phase, when the run got past it, is a result all the same
                    stop["before_perturbation"] = self.before_perturbation
                    mark = json.dumps(stop, indent=2) + "\n"
                    write_atomic(self.run_dir / DIVERGED_NAME, mark)
                    message = self.health.stop_message(self.presentation, self.saved)
                    log.writer.add_text("health", message, self.steps)
                    raise Diverged(message)
                # while the numbers are not finite, the last checkpoint stays the last good one
                holding = not self.health.healthy and self.health.stop_after is not None
                due = self.presentation % int(self.cfg.train.checkpoint_every) == 0
                if not holding and (due or self.presentation == total):
                    self.save()
        summary = finite_or_none(self.summary())  # strict JSON: null, never NaN
        write_atomic(self.summary_path, json.dumps(summary, indent=2, allow_nan=False) + "\n")
        return summary

    def _panel(self, watch: Watch, pres: Presentation) -> list:
        """The frames of robot 0's presentation (parallax.panel), small for TensorBoard."""
        title = f"presentation {self.presentation}: panel at {pres.distances[0]:.1f} m"
        truths = functools.partial(self.targets.truths, bodies=self.exp.parts)
        shown = watched(watch, pres, self.exp.parts, self.readout, title, truths)
        # without a video writer TensorBoard gets a montage of four frames: draw only those
        picks = None if can_write_video() else montage_picks(pictured_count(shown))
        return list(panel_frames(shown, width=PANEL_WIDTH, picks=picks))

    def _start(self) -> bool:
        """Resume from the checkpoint if asked and there is one (else start the metrics afresh),
        record the config, and set the switches of where the run stands; whether it resumed."""
        resumed = bool(self.cfg.resume) and self.restore()
        self.run_dir.mkdir(parents=True, exist_ok=True)
        # what a writer killed in the middle of a write left (parallax-train holds the folder's
        # lock: no one else is writing)
        remove_leftovers(self.run_dir, _WRITTEN)
        # a run that goes on from its last good checkpoint is no longer over
        (self.run_dir / DIVERGED_NAME).unlink(missing_ok=True)
        if not resumed:  # a start from scratch: no lines of an earlier start without a checkpoint
            for form in record_forms(self.metrics_path)[1:]:  # nor of a compacted record
                form.unlink(missing_ok=True)
            self.metrics_path.write_text("")
        config = OmegaConf.to_yaml(self.cfg, resolve=True)
        write_atomic(self.run_dir / RUN_CONFIG_NAME, config)
        if self.perturbed:
            self.exp.set_perturbation(True)
        self.exp.at_presentation(self.presentation)  # the bodies as they are by now
        self.health.skipped_seen = self.skipped_updates()
        return resumed

    def _switch_schedule(self) -> None:
        """§5's perturbation (the learnt state just before it kept for parallax-eval
        --checkpoint) at its presentation, and the bodies as they are at this one."""
        if self.presentation == self.perturbation_start:
            self.before_perturbation = self.metrics_summary()
            path = self.run_dir / checkpoint.BEFORE_PERTURBATION_NAME
            checkpoint.save_atomic(self.state_dict(), path)
            self.exp.set_perturbation(True)
        # a growth spurt: the body's stride grows; the robot's belief does not
        self.exp.at_presentation(self.presentation)


def _presentation_of(line: str) -> float:
    """The presentation a metrics.jsonl line belongs to; a line torn by a hard kill counts as
    after any checkpoint, so resuming drops it."""
    try:
        return json.loads(line)["presentation"]
    except (json.JSONDecodeError, KeyError, TypeError):
        return float("inf")
