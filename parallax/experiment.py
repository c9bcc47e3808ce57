"""One robot (or B robots in lockstep) living through stimulus presentations — paper §3.2, Fig. 3.

For each presentation: the world draws a texture and a distance and captures I0 at l0; then, for
each lateral position l_p of L, t_h iterations of

    render → retina → coder (state θ, reward −(eC+eF)) → policy update → action → dictionary update

and the pan reached at the last iteration is q_p. The vector s = [q1 … qr] and the distance go
to the distance learner. This module holds the parts of :func:`parallax.parts.build` and runs
presentations (:meth:`Experiment.run_presentation`, the loop; :mod:`parallax.lockstep` schedules
its steps on threads); `parallax.trainer` adds the schedule, metrics, logging and checkpoints,
and `parallax.tools.evaluate` the frozen measurements.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import cv2
import numpy as np
import torch
from omegaconf import DictConfig

from parallax.coding import CoderOutput
from parallax.envs.walk import walk_robots
from parallax.lockstep import Lockstep, robot_turns, stack_images
from parallax.metrics import position_label
from parallax.parts import body_walkers, build, distance_learner, seeds_for, truths_at, worlds

__all__ = [  # the parts' builders, for the tools that build one part alone
    "Experiment",
    "Presentation",
    "body_walkers",
    "distance_learner",
    "seeds_for",
    "truths_at",
    "worlds",
]


@dataclass
class Presentation:
    """What B robots did during one stimulus presentation."""

    lateral_positions: list[float]  # the list L used (metres)
    pans: np.ndarray  # (B, r) pan at the last iteration of each trial, q_p (deg)
    targets: np.ndarray  # (B, r) target pan α* at that iteration (deg)
    # (B, r) beyond the paper: the pan at the iteration of each trial whose image the coder
    # encoded best (highest reward −(eC+eF)); a readout of s that a runaway's end does not spoil
    best_pans: np.ndarray
    distances: np.ndarray  # (B,) metres
    textures: np.ndarray  # (B,) texture indices
    steps: int  # iterations per robot
    reward: float = float("nan")  # mean coder reward over the presentation
    errors: dict[str, float] = field(default_factory=dict)  # mean reconstruction error per scale
    policy_stats: dict[str, float] = field(default_factory=dict)
    last_view: np.ndarray | None = None  # robot 0's I0 beside its last image (for TensorBoard)
    start_pans: np.ndarray | None = None  # (B, r) pan at the first iteration of each trial (deg)
    # beyond the paper (§7): the positions of L a robot chose to visit, in order (indices into
    # L; the other positions' pans are NaN); None when it swept the whole list
    route: list[int] | None = None
    # seconds the loop's thread spent waiting in the lockstep (parallax.lockstep.WAITS): for
    # frames, for the dictionary step, encoding; the rest of its time is the policy's turn
    waits: dict[str, float] = field(default_factory=dict)

    @property
    def labels(self) -> list[str]:
        return [position_label(l) for l in self.lateral_positions]


class Experiment:
    """The world(s), coder, policy and distance learner of one run, built from a config."""

    def __init__(self, cfg: DictConfig, stimuli_split: str | None = None):
        self.cfg = cfg
        self.device = torch.device(cfg.device)
        if self.device.type == "cuda" and not torch.cuda.is_available():
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
        self.robots_per_turn = int(cfg.env.robots_per_turn)
        self.trial_length = int(cfg.env.trial_length)
        self.parts = build(cfg, stimuli_split)
        self.envs = self.parts.worlds
        self.coder, self.policy, self.distance = (
            self.parts.coder,
            self.parts.policy,
            self.parts.distance,
        )
        self.walkers, self.planner = self.parts.walkers, self.parts.planner
        self.explore_random = self.parts.explore
        self.stage = 0

    # --- curriculum and perturbation -------------------------------------------------------
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

    # --- the walk to the panel (beyond the paper, §7) ----------------------------------------
    @property
    def walks(self) -> bool:
        """Whether the distance learner's targets need walks (distance.targets=odometry)."""
        return self.distance.target_source.walks

    def walk(self) -> tuple[list[float | None], list[float]]:
        """After a sweep: each robot walks to its panel with probability
        distance.odometry.walk_fraction; its strides counted (None: it stayed) and the
        slip-free count (:func:`parallax.envs.walk.walk_robots`)."""
        fraction = self.distance.target_source.walk_fraction
        return walk_robots([env.physics for env in self.envs], self.walkers, fraction)

    def distance_truths(self, distances: np.ndarray) -> np.ndarray:
        """What a perfect distance learner answers for panels at ``distances`` (robot 0's body
        as it is now): the distances themselves, or the odometry's slip-free reading."""
        if not self.walks:
            return np.asarray(distances, dtype=np.float64)
        source = self.distance.target_source
        return truths_at(source, self.walkers[0], self.envs[0].physics, distances)

    def sweeps(self, explore: float) -> bool:
        """Whether this presentation sweeps all of L: always without a planner or before its
        queue is full, else with probability ``explore`` (drawn whenever there is a planner)."""
        if self.planner is None:
            return True
        draw = self.explore_random.random_sample()
        return not self.planner.is_ready or draw < explore

    def planned_route(self, readout_key: str) -> Callable[[list[int], Presentation], int | None]:
        """The planner as the ``route`` of :meth:`run_presentation`, reading s as
        ``readout_key`` (the Presentation field of train.distance_readout)."""
        planner = self.planner
        if planner is None:
            raise RuntimeError("no planner: movement.route is list")

        def choose(visited: list[int], so_far: Presentation) -> int | None:
            pans = getattr(so_far, readout_key)[0]
            return planner.next_position(visited, pans[visited])

        return choose

    def set_growth(self, grown: bool) -> None:
        """The bodies' strides before or after the growth spurt of env.walk."""
        for walker in self.walkers:
            walker.grown = bool(grown)

    # --- one presentation: the paper's loop -----------------------------------------------
    def run_presentation(
        self,
        learn: bool = True,
        greedy: bool = False,
        keep_view: bool = False,
        route: Callable[[list[int], Presentation], int | None] | None = None,
    ) -> Presentation:
        """All robots live through one presentation (paper §3.2, Fig. 3); learning on or frozen.

        Each iteration: the robots' images are encoded (state θ, reward −(eC+eF)), the policy
        learns from the step into them and acts, and the dictionaries take their step. A
        :class:`~parallax.lockstep.Lockstep` runs the worlds and the dictionary step on other
        threads meanwhile; every number is that of the plain sequence.

        ``route`` (one robot; beyond the paper, §7): instead of sweeping L, the robot asks
        ``route(visited, so_far)`` for the index into L of each next position — before the
        first trial, then at the end of each — with the positions visited so far and the
        presentation as it stands; None stops it there.
        """
        if not learn:  # frozen: acting must not move the policy's running feature statistics
            was_training = self.policy.training
            self.policy.eval()
            try:
                return self._run_presentation(False, greedy, keep_view, route)
            finally:
                self.policy.train(was_training)
        return self._run_presentation(True, greedy, keep_view, route)

    def _run_presentation(
        self,
        learn: bool,
        greedy: bool,
        keep_view: bool,
        route: Callable[[list[int], Presentation], int | None] | None,
    ) -> Presentation:
        learn_dictionaries = learn and self.coder.learn
        lateral = list(self.envs[0].task.lateral_positions)
        tally = _Tally(self.robots, lateral, self.trial_length, routed=route is not None)
        if route is not None:
            if self.robots != 1:
                raise ValueError(f"a chosen route needs env.robots=1, got {self.robots}")
            first = route([], tally.presentation(None, False))
            if first is None:
                raise ValueError("a route must visit at least one lateral position")
            self.envs[0].task.start_route(lateral[first])
        index_of = {l: k for k, l in enumerate(lateral)}
        valid = torch.ones(self.robots, dtype=torch.bool, device=self.device)  # every robot learns
        turns = robot_turns(self.robots, self.robots_per_turn)
        # each turn's last step (for the transition it learns from next) and θ(I0, I0)
        previous: list[_Step | None] = [None] * len(turns)
        reference_theta: list[torch.Tensor | None] = [None] * len(turns)
        obs: list[dict] = [{} for _ in range(self.robots)]  # each robot's latest observation
        running = True
        with Lockstep(self.envs, self.coder, turns) as world:
            world.reset()  # every robot's stimulus: I0 cached
            while running:
                for k, robots in enumerate(turns):
                    turn_obs, out, last = world.frames(k)  # I(t) encoded
                    obs[robots] = turn_obs
                    iteration, p = int(turn_obs[0]["iteration"]), int(turn_obs[0]["position_index"])
                    if route is not None:  # the episode's p-th position is this one of L
                        p = index_of[float(turn_obs[0]["lateral_position"])]
                    if iteration == 0:  # a new trial: the step into it crossed a reset, not learnt
                        previous[k] = None
                        if self.policy.uses_reference_state:  # with the dictionaries of I(t)
                            references = stack_images(turn_obs, "reference", self.device)
                            reference_theta[k] = self.coder.encode(references, robots).output.state
                    if learn_dictionaries and k == len(turns) - 1:
                        # the paper's last step, from every turn's encoding, started now to run
                        # during the policy's turn (the policy reads no dictionary) and waited
                        # for before the next iteration's first encoding
                        world.start_dictionary_step()
                    pans = np.array([float(o["pan"]) for o in turn_obs])
                    rewards = out.reward.cpu().numpy().astype(np.float64)
                    tally.encoded(turn_obs, out, pans, rewards, p, robots)
                    before = previous[k]
                    change = None
                    if before is not None:
                        change = (rewards, before.rewards, before.increments)
                    state = self.policy.state(
                        out.state, reference_theta[k], pans, lateral[p], change
                    )
                    if learn and before is not None:
                        transition = (before.state, before.action, out.reward, state, valid[robots])
                        tally.updated(self.policy.update(*transition))
                    if last:
                        running = False
                        continue
                    if route is not None and iteration == self.trial_length - 1:
                        tally.visited.append(p)
                        chosen = route(list(tally.visited), tally.presentation(obs, False))
                        if chosen is None:
                            running = False
                            break
                        if chosen in tally.visited:
                            raise ValueError(f"the route visits position {chosen} of L twice")
                        self.envs[0].task.visit_next(lateral[chosen])
                    action = self.policy.act(state, greedy=greedy)
                    increments = self.policy.action_values[action].cpu().numpy()
                    previous[k] = _Step(state, action, rewards, increments)
                    world.step(k, increments)
        presentation = tally.presentation(obs, keep_view)
        presentation.waits = dict(world.seconds)  # the last dictionary step's wait included
        return presentation

    # --- state -----------------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            "coder": self.coder.state_dict(),
            "policy": self.policy.state_dict(),
            "distance": self.distance.state_dict(),
            "env_random": [env.task.random.get_state() for env in self.envs],
            "stage": self.stage,
            # only a walking run draws from the walkers' streams, only a planning one plans
            **({"walkers": [w.state_dict() for w in self.walkers]} if self.walks else {}),
            **(
                {"planner": self.planner.state_dict(), "explore": self.explore_random.get_state()}
                if self.planner is not None
                else {}
            ),
        }

    def load_state_dict(self, state: dict) -> None:
        self.coder.load_state_dict(state["coder"])
        self.policy.load_state_dict(state["policy"])
        self.distance.load_state_dict(state["distance"])
        for env, rs in zip(self.envs, state["env_random"], strict=True):
            env.task.random.set_state(rs)
        if self.walks:
            for walker, walker_state in zip(self.walkers, state["walkers"], strict=True):
                walker.load_state_dict(walker_state)
        if self.planner is not None:
            self.planner.load_state_dict(state["planner"])
            self.explore_random.set_state(state["explore"])
        self.set_stage(state["stage"])

    def close(self) -> None:
        for env in self.envs:
            env.close()


class _Step(NamedTuple):
    """A robot's last step within the trial, for the transition the policy learns from next."""

    state: torch.Tensor  # (B, input_dim) what the policy acted on
    action: torch.Tensor  # (B,) the action indices
    rewards: np.ndarray  # (B,) the coder's rewards for the images acted on
    increments: np.ndarray  # (B,) the pan increments sent (deg)


class _Tally:
    """What one presentation reports (:class:`Presentation`), gathered iteration by iteration."""

    def __init__(
        self, robots: int, lateral: list[float], trial_length: int, routed: bool = False
    ) -> None:
        self.lateral, self.trial_length = lateral, trial_length
        shape = (robots, len(lateral))
        # on a chosen route the positions never visited keep NaN
        blank = np.full(shape, np.nan) if routed else np.zeros(shape)
        self.pans, self.targets, self.start_pans = blank.copy(), blank.copy(), blank.copy()
        self.best_pans, self.best_rewards = blank.copy(), np.full(shape, -np.inf)
        self.visited: list[int] | None = [] if routed else None
        # sums over robots and iterations, and the robot-encodings they add up
        self.reward_sum, self.error_sums, self.encodings = 0.0, {}, 0
        self.stat_sums: dict[str, float] = {}
        self.updates = 0

    def encoded(
        self,
        obs: list[dict],
        out: CoderOutput,
        pans: np.ndarray,
        rewards: np.ndarray,
        p: int,
        robots: slice = slice(None),
    ) -> None:
        """The coder's output ``out`` (rewards in float64) for the images of ``robots`` (all by
        default) seen at ``pans``, at position ``p`` of L."""
        iteration = int(obs[0]["iteration"])
        self.reward_sum += float(out.reward.sum())
        for scale, e in out.errors.items():
            self.error_sums[scale] = self.error_sums.get(scale, 0.0) + float(e.sum())
        self.encodings += len(rewards)
        if iteration == 0:
            self.start_pans[robots, p] = pans
        best = self.best_rewards[robots, p]
        better = rewards > best  # ties keep the earlier pan
        best[better] = rewards[better]
        self.best_rewards[robots, p] = best
        best_pans = self.best_pans[robots, p]
        best_pans[better] = pans[better]
        self.best_pans[robots, p] = best_pans
        if iteration == self.trial_length - 1:  # q_p, and α* there
            self.pans[robots, p] = pans
            self.targets[robots, p] = [float(o["target_pan"]) for o in obs]

    def updated(self, stats: dict[str, float]) -> None:
        for k, v in stats.items():
            self.stat_sums[k] = self.stat_sums.get(k, 0.0) + float(v)
        self.updates += 1

    def presentation(self, obs: list[dict] | None, keep_view: bool) -> Presentation:
        """The record, from the tally and the last observations (None: before the first; the
        distances and textures are then unknown, NaN and −1)."""
        view = None
        if keep_view:
            view = np.concatenate([obs[0]["reference"], obs[0]["image"]], axis=1)
        updates, encodings = self.updates, max(self.encodings, 1)
        robots = self.pans.shape[0]
        return Presentation(
            lateral_positions=self.lateral,
            pans=self.pans,
            targets=self.targets,
            best_pans=self.best_pans,
            distances=np.array([float(o["distance"]) for o in obs] if obs else [np.nan] * robots),
            textures=np.array([int(o["texture_index"]) for o in obs] if obs else [-1] * robots),
            steps=self.encodings // robots,
            reward=self.reward_sum / encodings,
            errors={k: v / encodings for k, v in self.error_sums.items()},
            policy_stats={k: v / updates for k, v in self.stat_sums.items()} if updates else {},
            last_view=view,
            start_pans=self.start_pans,
            route=None if self.visited is None else list(self.visited),
        )
