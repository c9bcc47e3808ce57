"""The parts of one run, built in one place from a composed config (paper §3.2, Fig. 3).

:func:`build` returns the run's :class:`Parts`: B worlds, the coder, the policy, the distance
learner, the bodies' walkers and, for a planned route (§7), the planner and its explore stream.
Every part's seed comes from one user-facing seed through a small named tree (:class:`Seeds`):
the run's seed spawns one child per robot's world, then one each for the coder, the policy and
the distance learner, one whose own children seed the walkers, and one for the explore stream.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

import parallax.envs
from parallax.coding import MultiScaleCoder
from parallax.distance import DistanceLearner
from parallax.distance.planner import MovementPlanner
from parallax.envs.settings import growth_start
from parallax.envs.walk import Walker
from parallax.policy import NaturalActorCritic

#: The settings of cfg.env that are not the world's own (parallax.envs.load's): how many robots
#: there are and in what turns they step (the lockstep's), and the body's walk (the walkers').
NOT_THE_WORLDS = ("robots", "robots_per_turn", "walk")


def seeds_for(seed: int, count: int) -> list[int]:
    """Independent integer seeds, the first ``count`` children of ``seed``'s SeedSequence (the
    k-th child is the same whatever ``count``)."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(int(seed)).spawn(count)]


@dataclass(frozen=True)
class Seeds:
    """The run's seed tree: the children of the run's seed, in this order."""

    worlds: tuple[int, ...]  # one per robot's world
    coder: int
    policy: int
    distance: int
    walkers: tuple[int, ...]  # the children of the next child, one per robot's body
    explore: int  # the planned route's stream: when it sweeps all of L instead

    @classmethod
    def of(cls, seed: int, robots: int) -> Seeds:
        children = seeds_for(seed, robots + 5)
        coder, policy, distance, walkers, explore = children[robots:]
        return cls(
            worlds=tuple(children[:robots]),
            coder=coder,
            policy=policy,
            distance=distance,
            walkers=tuple(seeds_for(walkers, robots)),
            explore=explore % 2**32,
        )


def run_seeds(cfg: DictConfig) -> Seeds:
    return Seeds.of(int(cfg.seed), int(cfg.env.robots))


def distance_learner(cfg: DictConfig, seeds: Seeds | None = None) -> DistanceLearner:
    """The run's distance learner (paper §3.5), fresh, with its seed of the run's tree."""
    return instantiate(
        cfg.distance,
        lateral_positions=[float(l) for l in cfg.curriculum.lateral_positions],
        seed=(seeds or run_seeds(cfg)).distance,
    )


def world_settings(cfg: DictConfig) -> dict:
    """cfg.env as the keyword arguments of ``parallax.envs.load``."""
    env = OmegaConf.to_container(cfg.env, resolve=True)
    return {key: value for key, value in env.items() if key not in NOT_THE_WORLDS}


def worlds(
    cfg: DictConfig,
    lateral_positions: list[float],
    stimuli_split: str | None = None,
    seeds: Seeds | None = None,
):
    """The run's B worlds (``parallax.envs.load``), unperturbed, robot b's with its seed of the
    run's tree; ``stimuli_split`` replaces env.stimuli.split (parallax-eval: heldout)."""
    settings = world_settings(cfg)
    if stimuli_split is not None:
        settings["stimuli"] = {**settings["stimuli"], "split": stimuli_split}
    return [
        parallax.envs.load(
            seed=seed,
            lateral_positions=lateral_positions,
            camera_rotation_deg=0.0,
            blur_sigma=0.0,
            rotation_axis=cfg.perturbation.rotation_axis,
            **settings,
        )
        for seed in (seeds or run_seeds(cfg)).worlds
    ]


def body_walkers(cfg: DictConfig, seeds: Seeds | None = None) -> list[Walker]:
    """Each robot's walk to the panel (env.walk; beyond the paper, §7), with its own slip
    stream and the presentation of its growth spurt."""
    walk = cfg.env.walk
    return [
        Walker(
            seed=seed,
            stride_m=float(walk.stride_m),
            stride_slip=float(walk.stride_slip),
            substeps=int(walk.substeps),
            growth_factor=float(walk.growth_factor),
            growth_start=growth_start(cfg),
        )
        for seed in (seeds or run_seeds(cfg)).walkers
    ]


@dataclass
class Parts:
    """What one run is made of (:func:`build`)."""

    worlds: list  # B dm_control environments
    coder: MultiScaleCoder
    policy: NaturalActorCritic
    distance: DistanceLearner
    walkers: list[Walker]
    planner: MovementPlanner | None  # a planned route (movement.route=planned), else None
    explore: np.random.RandomState  # when a planning robot sweeps all of L instead
    seeds: Seeds


def build(cfg: DictConfig, stimuli_split: str | None = None) -> Parts:
    """The run's parts, fresh, on cfg.device; the worlds on the curriculum's first list."""
    device = torch.device(cfg.device)
    seeds = run_seeds(cfg)
    lateral = [float(l) for l in cfg.curriculum.lateral_positions]
    first_list = [float(l) for l in (cfg.curriculum.get("stages") or [lateral])[0]]
    envs = worlds(cfg, first_list, stimuli_split, seeds)
    coder = instantiate(cfg.coder, image_size=int(cfg.env.image_size), seed=seeds.coder)
    coder = coder.to(device)
    policy = instantiate(
        cfg.policy, state_dim=coder.state_dim, num_scales=len(cfg.coder.scales), seed=seeds.policy
    ).to(device)
    distance = distance_learner(cfg, seeds).to(device)
    planner = None
    if cfg.movement.route == "planned":
        planner = MovementPlanner(
            lateral,
            queue_size=int(cfg.distance.queue_size),
            price_per_trial=float(cfg.movement.price_per_trial),
            price_per_cm=float(cfg.movement.price_per_cm),
        )
    return Parts(
        worlds=envs,
        coder=coder,
        policy=policy,
        distance=distance,
        walkers=body_walkers(cfg, seeds),
        planner=planner,
        explore=np.random.RandomState(seeds.explore),
        seeds=seeds,
    )
