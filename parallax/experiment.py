"""One robot (or B robots in lockstep) living through stimulus presentations — paper §3.2, Fig. 3.

For each presentation: the world draws a texture and a distance and captures I0 at l0; then, for
each lateral position l_p of L, t_h iterations of

    render → retina → coder (state θ, reward −(eC+eF)) → policy update → action → dictionary update

and the pan reached at the last iteration is q_p. The vector s = [q1 … qr] and the distance go
to the distance learner. This module builds the four parts from a composed config and runs
presentations; `parallax.trainer` adds the schedule, metrics, logging and checkpoints, and
`parallax.tools.evaluate` the frozen measurements.
"""

from __future__ import annotations

from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

import parallax.envs
from parallax.coding import CoderOutput, Encoding
from parallax.metrics import position_label
from parallax.policy.features import REFERENCE_MODE


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

    @property
    def labels(self) -> list[str]:
        return [position_label(l) for l in self.lateral_positions]


def seeds_for(seed: int, count: int) -> list[int]:
    """Independent integer seeds for the parts of one run, from one user-facing seed."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(int(seed)).spawn(count)]


class Experiment:
    """The world(s), coder, policy and distance learner of one run, built from a config."""

    #: Robots whose frames are encoded together in a lockstep (the last chunk may be smaller): 2–4
    #: was fastest at B = 16 on 2 cores (about 260 robot-iterations/s, against 204 for one chunk
    #: of 16 and 239 for chunks of 1: small chunks overlap more with rendering but cost more calls).
    ENCODE_CHUNK = 4
    #: Start each iteration's dictionary step on the coder's helper thread as soon as its frames
    #: are encoded, so that it runs during the policy's turn (when only this thread works) and
    #: the render; False: on this thread once the actions are sent. Same numbers either way
    #: (tests/test_experiment.py); it takes 1.4–2.3 ms of CPU per step off this thread at B = 1.
    EARLY_DICTIONARY_STEP = True

    def __init__(self, cfg: DictConfig, stimuli_split: str | None = None):
        self.cfg = cfg
        self.device = torch.device(cfg.device)
        if self.device.type == "cuda" and not torch.cuda.is_available():
            raise RuntimeError(
                "device=cuda was asked for but torch sees no CUDA device; use device=cpu"
            )
        # OpenCV's calls in a step (the retina's cvtColor and pyrDown, the §5 blur) take tens of
        # µs on images this small, and between them its worker thread spun: 0.8–0.9 ms of CPU per
        # step at B = 1 (per-thread CPU times, two runs each way), taken from the threads that
        # render and encode. Without workers the calls run here; their results are the same
        # (tests/coding/test_retina.py).
        cv2.setNumThreads(0)
        self.lateral_positions = [float(l) for l in cfg.curriculum.lateral_positions]
        stages = cfg.curriculum.get("stages") or [self.lateral_positions]
        self.stages = [[float(l) for l in stage] for stage in stages]

        env_kwargs = OmegaConf.to_container(cfg.env, resolve=True)
        self.robots = int(env_kwargs.pop("robots", 1))
        if stimuli_split is not None:
            env_kwargs["stimuli"] = {**env_kwargs["stimuli"], "split": stimuli_split}
        self.trial_length = int(env_kwargs["trial_length"])
        # One seed per robot's world, then the coder, the policy and the distance learner.
        seeds = seeds_for(cfg.seed, self.robots + 3)
        self.envs = [
            parallax.envs.load(
                seed=seeds[i],
                lateral_positions=self.stages[0],
                camera_rotation_deg=0.0,
                blur_sigma=0.0,
                rotation_axis=cfg.perturbation.rotation_axis,
                **env_kwargs,
            )
            for i in range(self.robots)
        ]
        self.coder = instantiate(
            cfg.coder, image_size=int(cfg.env.image_size), seed=seeds[self.robots]
        ).to(self.device)
        self.policy = instantiate(
            cfg.policy,
            state_dim=self.coder.state_dim,
            num_scales=len(cfg.coder.scales),
            seed=seeds[self.robots + 1],
        ).to(self.device)
        self.distance = instantiate(
            cfg.distance, lateral_positions=self.lateral_positions, seed=seeds[self.robots + 2]
        )
        if hasattr(self.distance, "to"):  # DistanceLearner.to, or an nn.Module
            self.distance.to(self.device)
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
        """Trials start from the jittered pan of ``env.initial_pan_jitter_deg…`` (on) or from 0."""
        for env in self.envs:
            env.task.set_start_jitter(on)

    def set_perturbation(self, on: bool) -> None:
        p = self.cfg.perturbation
        for env in self.envs:
            env.task.set_perturbation(
                camera_rotation_deg=float(p.camera_rotation_deg) if on else 0.0,
                blur_sigma=float(p.blur_sigma) if on else 0.0,
            )

    # --- one presentation ------------------------------------------------------------------
    def _images(self, observations: list[dict], key: str) -> torch.Tensor:
        return torch.from_numpy(np.stack([o[key] for o in observations])).to(self.device)

    @property
    def uses_reference_states(self) -> bool:
        """The policy sees θ(t) − θ_ref (``policy.feature_norm=difference``, beyond the paper)."""
        return self.policy.feature_norm == REFERENCE_MODE

    def reference_states(self, reference: torch.Tensor) -> torch.Tensor:
        """θ_ref (B, state_dim): the pooled activity of (I0, I0), the stimulus at zero disparity,
        with the current dictionaries and without learning (the coder's reference must be set)."""
        return self.coder(reference, learn=False).state

    def policy_state(
        self,
        theta: torch.Tensor,
        reference_state: torch.Tensor | None,
        pans_deg: np.ndarray,
        lateral_m: float,
        reward_change: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> torch.Tensor:
        """What the policy acts on: θ (B, state_dim), minus θ_ref with ``feature_norm=difference``,
        then the eye-position entry when ``policy.eye_position_reference_m`` > 0, then the
        reward-change entry when ``policy.reward_change_gain`` > 0 (all three beyond the paper),
        for the robots' pans (B,) at their shared lateral position. ``reward_change`` is
        (rewards, previous rewards, previous pan increments), each (B,); None: no previous step
        (the entry is 0)."""
        state = theta if reference_state is None else theta - reference_state
        extra = []
        if self.policy.eye_position_dims:
            pans = torch.as_tensor(np.asarray(pans_deg, dtype=np.float64))
            extra.append(self.policy.eye_position_feature(pans, lateral_m))
        if self.policy.reward_change_dims:
            if reward_change is None:
                extra.append(
                    torch.zeros(
                        state.shape[0],
                        1,
                        dtype=self.policy.actor.dtype,
                        device=self.policy.actor.device,
                    )
                )
            else:
                extra.append(self.policy.reward_change_feature(*reward_change))
        return torch.cat([state, *[e.to(state.dtype) for e in extra]], dim=1) if extra else state

    def run_presentation(
        self, learn: bool = True, greedy: bool = False, keep_view: bool = False
    ) -> Presentation:
        """All robots live through one presentation; learning on or frozen.

        The worlds step on the GL thread (:func:`parallax.envs.gl_thread`) while this thread
        works: the dictionary step of iteration t runs on the coder's helper thread (CPU) while
        the policy learns and acts and the frames of t + 1 render, and the robots' frames are
        encoded chunk by chunk as they arrive. Every value is computed as in
        the plain sequence render → encode → policy → dictionary step, in the same order per
        robot and per dictionary, so the results do not depend on it (tests/test_experiment;
        with one torch thread, ``train.threads=1``, the default: with more, the matrix library
        may split a product of a chunk's rows otherwise than one of all rows).
        """
        learn_dictionaries = learn and self.coder.learn
        world = parallax.envs.gl_thread()
        futures = [world.submit(env.reset) for env in self.envs]
        # every robot's I0 before any encoding
        self.coder.set_reference(
            self._images([f.result().observation for f in futures], "reference")
        )
        timesteps, encodings = self._gather(futures)
        obs = [ts.observation for ts in timesteps]
        lateral = list(self.envs[0].task.lateral_positions)
        B, r, t_h = self.robots, len(lateral), self.trial_length
        pans, targets, start_pans = np.zeros((B, r)), np.zeros((B, r)), np.zeros((B, r))
        best_pans, best_rewards = np.zeros((B, r)), np.full((B, r), -np.inf)

        prev_state = prev_action = prev_rewards = prev_increments = None
        reference_state = None
        valid = torch.ones(B, dtype=torch.bool, device=self.device)  # every robot learns every step
        reward_sum, error_sums, n_enc = 0.0, {}, 0
        stat_sums: dict[str, float] = {}
        n_updates = steps = 0
        learning: Future | None = None  # a dictionary step running on the coder's helper thread

        def finish_dictionary_step() -> None:
            """This iteration's dictionary step done: waited for, or taken now on this thread."""
            nonlocal learning
            if learning is not None:
                learning.result()
                learning = None
            elif learn_dictionaries:
                self.coder.learn_from(encodings)

        try:
            while True:
                iteration = int(obs[0]["iteration"])
                if self.uses_reference_states and iteration == 0:
                    # once per trial, with the dictionaries this step's frames were encoded with
                    reference_state = self.reference_states(self._images(obs, "reference"))
                if learn_dictionaries and self.EARLY_DICTIONARY_STEP:
                    # this iteration's dictionary step, on the coder's helper thread while the policy
                    # learns and acts (the world and the helper would otherwise wait) and the world
                    # renders; waited for before anything reads the dictionaries again
                    learning = self.coder.learn_from_async(encodings)
                out = (
                    encodings[0].output
                    if len(encodings) == 1
                    else CoderOutput.join([encoding.output for encoding in encodings])
                )
                reward_sum += float(out.reward.mean())
                for scale, e in out.errors.items():
                    error_sums[scale] = error_sums.get(scale, 0.0) + float(e.mean())
                n_enc += 1
                p = int(obs[0]["position_index"])
                current_pans = np.array([float(o["pan"]) for o in obs])
                if iteration == 0:
                    start_pans[:, p] = current_pans
                rewards = out.reward.cpu().numpy().astype(np.float64)
                better = rewards > best_rewards[:, p]  # ties keep the earlier pan
                best_rewards[better, p] = rewards[better]
                best_pans[better, p] = current_pans[better]
                # the last step's reward change, within the trial only (none at its first iteration)
                change = None if iteration == 0 else (rewards, prev_rewards, prev_increments)
                state = self.policy_state(
                    out.state, reference_state, current_pans, lateral[p], change
                )
                # Robots move in lockstep, so they cross a trial boundary together; the transition into
                # iteration 0 crosses a reset (new stimulus or new lateral position) and is not learnt.
                if learn and prev_state is not None and iteration > 0:
                    stats = self.policy.update(prev_state, prev_action, out.reward, state, valid)
                    for k, v in stats.items():
                        stat_sums[k] = stat_sums.get(k, 0.0) + float(v)
                    n_updates += 1
                if iteration == t_h - 1:
                    pans[:, p] = current_pans
                    targets[:, p] = [float(o["target_pan"]) for o in obs]
                if timesteps[0].last():
                    finish_dictionary_step()
                    break
                action = self.policy.act(state, greedy=greedy)
                increments = self.policy.action_values[action].cpu().numpy()
                futures = [
                    world.submit(env.step, float(a)) for env, a in zip(self.envs, increments)
                ]
                finish_dictionary_step()  # while the next frames render; they are encoded with it
                timesteps, encodings = self._gather(futures)
                obs = [ts.observation for ts in timesteps]
                prev_state, prev_action, prev_rewards, prev_increments = (
                    state,
                    action,
                    rewards,
                    increments,
                )
                steps += 1
        finally:
            if learning is not None:
                wait([learning])  # never leave a dictionary step running behind an error

        view = None
        if keep_view:
            view = np.concatenate([obs[0]["reference"], obs[0]["image"]], axis=1)
        return Presentation(
            lateral_positions=lateral,
            pans=pans,
            targets=targets,
            best_pans=best_pans,
            distances=np.array([float(o["distance"]) for o in obs]),
            textures=np.array([int(o["texture_index"]) for o in obs]),
            steps=steps + 1,
            reward=reward_sum / n_enc,
            errors={k: v / n_enc for k, v in error_sums.items()},
            policy_stats={k: v / n_updates for k, v in stat_sums.items()} if n_updates else {},
            last_view=view,
            start_pans=start_pans,
        )

    def _gather(self, futures: list[Future]) -> tuple[list[Any], list[Encoding]]:
        """The robots' time steps from ``futures`` and the encodings of their frames, chunk by
        chunk in robot order, each chunk as soon as its frames are there."""
        timesteps: list[Any] = []
        encodings: list[Encoding] = []
        chunk = self.ENCODE_CHUNK if self.robots > 1 else 1
        for first in range(0, self.robots, chunk):
            robots = slice(first, min(first + chunk, self.robots))
            arrived = [future.result() for future in futures[robots]]
            timesteps += arrived
            images = self._images([ts.observation for ts in arrived], "image")
            encodings.append(self.coder.encode(images, robots))
        return timesteps, encodings

    # --- state -----------------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            "coder": self.coder.state_dict(),
            "policy": self.policy.state_dict(),
            "distance": self.distance.state_dict(),
            "env_random": [env.task.random.get_state() for env in self.envs],
            "stage": self.stage,
        }

    def load_state_dict(self, state: dict) -> None:
        self.coder.load_state_dict(state["coder"])
        self.policy.load_state_dict(state["policy"])
        self.distance.load_state_dict(state["distance"])
        for env, rs in zip(self.envs, state["env_random"], strict=True):
            env.task.random.set_state(rs)
        self.set_stage(state["stage"])

    def close(self) -> None:
        for env in self.envs:
            env.close()
