"""One run's robots living through stimulus presentations — paper §3.2, Fig. 3, and §5.

An :class:`Experiment` holds the run's parts (:func:`parallax.parts.build`) and what changes over
a run without being learnt: the curriculum's stage (its list L), the start jitter, §5's
perturbation and the bodies' growth. :meth:`Experiment.run_presentation` runs the paper's loop
(:func:`parallax.loop.presentation`) with its steps scheduled on threads
(:class:`parallax.lockstep.Lockstep`); `parallax.trainer` adds the schedule, the distance step,
metrics, logging and checkpoints, and `parallax.tools.evaluate` the frozen measurements.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import torch
from omegaconf import DictConfig

from parallax import loop
from parallax.coding import MultiScaleCoder
from parallax.distance import DistanceLearner
from parallax.distance.planner import MovementPlanner
from parallax.executor import Executor
from parallax.lockstep import Lockstep, robot_turns
from parallax.parts import Parts, build
from parallax.policy import NaturalActorCritic
from parallax.presentation import Presentation
from parallax.routes import SWEEP, Route


class Experiment:
    """The parts of one run (built from ``cfg`` unless given) and the switches of its schedule."""

    def __init__(
        self, cfg: DictConfig, stimuli_split: str | None = None, parts: Parts | None = None
    ):
        self.cfg = cfg
        if torch.device(cfg.device).type == "cuda" and not torch.cuda.is_available():
            raise RuntimeError(
                "device=cuda was asked for but torch sees no CUDA device; use device=cpu"
            )
        # OpenCV's calls in a step (the retina's cvtColor and pyrDown, the §5 blur) are tiny on
        # images this small, and between them its worker threads spin on the cores that render
        # and encode. Without workers each call runs on its caller's thread, with the same
        # results (tests/coding/test_retina.py).
        cv2.setNumThreads(0)
        self.lateral_positions = [float(l) for l in cfg.curriculum.lateral_positions]
        stages = cfg.curriculum.get("stages") or [self.lateral_positions]
        self.stages = [[float(l) for l in stage] for stage in stages]
        self.robots = int(cfg.env.robots)
        self.trial_length = int(cfg.env.trial_length)
        self.turns = robot_turns(self.robots, int(cfg.env.robots_per_turn))
        self.parts = build(cfg, stimuli_split) if parts is None else parts
        self.stage = 0

    # --- the parts -------------------------------------------------------------------------
    @property
    def envs(self) -> list:
        return self.parts.worlds

    @property
    def coder(self) -> MultiScaleCoder:
        return self.parts.coder

    @property
    def policy(self) -> NaturalActorCritic:
        return self.parts.policy

    @property
    def distance(self) -> DistanceLearner:
        return self.parts.distance

    @property
    def planner(self) -> MovementPlanner | None:
        return self.parts.planner

    @property
    def walks(self) -> bool:
        """Whether the distance learner's targets need walks (distance.targets=odometry)."""
        return self.distance.target_source.walks

    # --- curriculum, perturbation and growth -----------------------------------------------
    def set_stage(self, stage: int) -> None:
        self.stage = int(stage)
        for env in self.envs:
            env.task.set_lateral_positions(self.stages[self.stage])

    @property
    def on_final_list(self) -> bool:
        return self.stage == len(self.stages) - 1

    def set_start_jitter(self, on: bool) -> None:
        """Trials start from the jittered pan of ``env.initial_pan_jitter_deg`` (on) or from 0."""
        for env in self.envs:
            env.task.set_start_jitter(on)

    def set_perturbation(self, on: bool) -> None:
        p = self.cfg.perturbation
        for env in self.envs:
            env.task.set_perturbation(
                camera_rotation_deg=float(p.camera_rotation_deg) if on else 0.0,
                blur_sigma=float(p.blur_sigma) if on else 0.0,
            )

    def at_presentation(self, presentation: int) -> None:
        """Presentation ``presentation`` (0-based) is next: the bodies' strides before or after
        the growth spurt of env.walk."""
        for walker in self.parts.walkers:
            walker.at_presentation(presentation)

    # --- one presentation: the paper's loop -----------------------------------------------
    def run_presentation(
        self,
        learn: bool = True,
        greedy: bool = False,
        keep_view: bool = False,
        route: Route = SWEEP,
        watch: Callable[[Executor], Executor] | None = None,
    ) -> Presentation:
        """All robots live through one presentation (:func:`parallax.loop.presentation`), its
        steps scheduled on threads by a :class:`~parallax.lockstep.Lockstep`; learning on or
        frozen; on ``route`` (:mod:`parallax.routes`: a chosen one takes one robot, §7);
        ``watch`` (e.g. :meth:`parallax.watch.Watch.around`) stands in front of the lockstep."""
        run = Lockstep(self.envs, self.coder, self.turns)
        executor = run if watch is None else watch(run)
        pres = loop.presentation(
            self.parts, executor, learn=learn, greedy=greedy, route=route, keep_view=keep_view
        )
        pres.waits = dict(run.seconds)  # the last dictionary step's wait included
        return pres

    # --- state -----------------------------------------------------------------------------
    def state_dict(self) -> dict:
        parts = self.parts
        return {
            "coder": parts.coder.state_dict(),
            "policy": parts.policy.state_dict(),
            "distance": parts.distance.state_dict(),
            "env_random": [env.task.random_state() for env in parts.worlds],
            "stage": self.stage,
            # only a walking run draws from the walkers' streams, only a planning one plans
            **({"walkers": [w.state_dict() for w in parts.walkers]} if self.walks else {}),
            **(
                {"planner": parts.planner.state_dict(), "explore": parts.explore.get_state()}
                if parts.planner is not None
                else {}
            ),
        }

    def load_state_dict(self, state: dict) -> None:
        parts = self.parts
        parts.coder.load_state_dict(state["coder"])
        parts.policy.load_state_dict(state["policy"])
        parts.distance.load_state_dict(state["distance"])
        for env, rs in zip(parts.worlds, state["env_random"], strict=True):
            env.task.set_random_state(rs)
        if self.walks:
            for walker, walker_state in zip(parts.walkers, state["walkers"], strict=True):
                walker.load_state_dict(walker_state)
        if parts.planner is not None:
            parts.planner.load_state_dict(state["planner"])
            parts.explore.set_state(state["explore"])
        self.set_stage(state["stage"])

    def close(self) -> None:
        for env in self.envs:
            env.close()
