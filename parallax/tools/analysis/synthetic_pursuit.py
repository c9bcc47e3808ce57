"""A small stand-in for the pursuit task of §3.4, to test the learner and choose its step sizes.

The state is a 1-D pan offset x (degrees) between where the eye points and where it should
point; a pan increment a ∈ A moves it to x − a, and the reward observed in the new state is
−|x − a| (the paper's −(eC + eF) also grows with the residual disparity). Episodes of fixed
length start from a uniform random offset, like the start of a lateral position (§3.2).

What the learner sees imitates pooled activities θ = [θC; θF] (eqs. 3, 5): per scale a bank of
non-negative units, part of them tuned to the offset (Gaussian tuning around preferred offsets,
broad for the coarse scale, narrow for the fine one), the rest untuned; every unit's response is
multiplied by a per-episode "texture" gain (a new stimulus changes which bases fire) and by
per-step noise, and the bank is scaled so that the mean activity is about 0.006 per entry.

Everything runs batched over B robots with an explicit ``torch.Generator``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import torch

from parallax.policy.natural_actor_critic import NaturalActorCritic

#: Offsets closer to zero than this are left out of the "correcting action" score: there the
#: best move is to stay (or a half step), which is a matter of taste rather than of learning.
DEAD_ZONE_DEG = 0.05


@dataclass(frozen=True)
class PursuitTaskConfig:
    units_per_scale: int = 288
    num_scales: int = 2
    max_offset_deg: float = 1.0
    episode_length: int = 20
    tuning_width_deg: tuple[float, ...] = (0.4, 0.1)  # coarse, fine
    tuned_fraction: float = 0.5
    mean_activity: float = 0.006
    texture_spread: float = 0.3  # σ of the log per-episode unit gains
    noise: float = 0.2  # relative per-step noise

    @property
    def state_dim(self) -> int:
        return self.units_per_scale * self.num_scales


class SyntheticPursuit:
    """B independent robots, each following one offset through episodes of fixed length."""

    def __init__(self, num_robots: int, config: PursuitTaskConfig, seed: int) -> None:
        if num_robots <= 0:
            raise ValueError(f"num_robots must be positive, got {num_robots!r}")
        if len(config.tuning_width_deg) != config.num_scales:
            raise ValueError(
                f"tuning_width_deg needs one width per scale "
                f"({config.num_scales}), got {config.tuning_width_deg!r}"
            )
        self.config = config
        self.num_robots = num_robots
        self.generator = torch.Generator().manual_seed(seed)
        units, span = config.state_dim, config.max_offset_deg
        self.preferred = (torch.rand(units, generator=self.generator) * 2 - 1) * (span + 0.2)
        self.width = torch.tensor(config.tuning_width_deg).repeat_interleave(config.units_per_scale)
        self.tuned = torch.rand(units, generator=self.generator) < config.tuned_fraction
        grid = torch.linspace(-span, span, 101)
        typical = self._responses(grid).mean() * math.exp(config.texture_spread**2 / 2)
        self.activity_scale = config.mean_activity / float(typical)
        self.offset = torch.zeros(num_robots)
        self.texture = torch.ones(num_robots, units)
        self.step_in_episode = torch.zeros(num_robots, dtype=torch.int64)
        self._new_episode(torch.ones(num_robots, dtype=torch.bool))

    def _new_episode(self, rows: torch.Tensor) -> None:
        count, cfg = int(rows.sum()), self.config
        start = (torch.rand(count, generator=self.generator) * 2 - 1) * cfg.max_offset_deg
        gains = torch.exp(
            cfg.texture_spread * torch.randn(count, cfg.state_dim, generator=self.generator)
        )
        self.offset[rows] = start
        self.texture[rows] = gains
        self.step_in_episode[rows] = 0

    def activities(self, offset: torch.Tensor, texture: torch.Tensor) -> torch.Tensor:
        """Pooled-activity-like states (B, state_dim) for offsets (B,) and textures (B, D)."""
        response = self._responses(offset)
        noise = 1 + self.config.noise * torch.randn(response.shape, generator=self.generator)
        return (response * texture * noise).clamp(min=0) * self.activity_scale

    def _responses(self, offset: torch.Tensor) -> torch.Tensor:
        """Noise-free unit responses (B, D), before texture gains and scaling."""
        tuning = torch.exp(-0.5 * ((offset.unsqueeze(1) - self.preferred) / self.width) ** 2)
        return torch.where(self.tuned, 0.2 + tuning, torch.full_like(tuning, 0.5))

    def observe(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The current states and the rewards −|x| observed in them."""
        return self.activities(self.offset, self.texture), -self.offset.abs()

    def step(self, pan_deg: torch.Tensor) -> torch.Tensor:
        """Applies the pan increments; returns which robots then start a new episode."""
        limit = self.config.max_offset_deg + 0.2
        self.offset = (self.offset - pan_deg.float()).clamp(-limit, limit)
        self.step_in_episode += 1
        restart = self.step_in_episode >= self.config.episode_length
        if bool(restart.any()):
            self._new_episode(restart)
        return restart


def correcting_fraction(
    policy: NaturalActorCritic,
    task: SyntheticPursuit,
    num_offsets: int = 200,
    textures_per_offset: int = 4,
) -> float:
    """Fraction of evaluation states (|x| ≥ DEAD_ZONE_DEG) where the greedy action reduces |x|."""
    span = task.config.max_offset_deg
    grid = torch.linspace(-span, span, num_offsets)
    grid = grid[grid.abs() >= DEAD_ZONE_DEG].repeat(textures_per_offset)
    texture = torch.exp(
        task.config.texture_spread
        * torch.randn(grid.shape[0], task.config.state_dim, generator=task.generator)
    )
    was_training = policy.training
    policy.eval()
    pan = policy.action_values[policy.act(task.activities(grid, texture), greedy=True)]
    policy.train(was_training)
    return float(((grid - pan.float()).abs() < grid.abs()).float().mean())


class CurvePoint(NamedTuple):
    step: int
    reward: float  # mean reward of the sampling policy over the last window of steps
    entropy: float  # mean policy entropy over that window (log 7 ≈ 1.95 is uniform)
    correcting: float  # correcting_fraction of the greedy policy at this step


def train_on_synthetic_pursuit(
    policy: NaturalActorCritic, task: SyntheticPursuit, steps: int, evaluate_every: int = 0
) -> list[CurvePoint]:
    """Runs the trainer's loop (update the last transition, then act) for ``steps`` steps.

    Returns the learning curve, one point every ``evaluate_every`` steps (none if 0) and one at
    the end.
    """
    curve: list[CurvePoint] = []
    previous_state, previous_action = None, None
    valid = torch.zeros(task.num_robots, dtype=torch.bool)
    reward_sum, entropy_sum, window = 0.0, 0.0, 0
    for step in range(1, steps + 1):
        state, reward = task.observe()
        if previous_state is not None:
            stats = policy.update(previous_state, previous_action, reward, state, valid)
            entropy_sum += stats["entropy"]
        reward_sum += float(reward.mean())
        window += 1
        action = policy.act(state)
        restarted = task.step(policy.action_values[action])
        # The transition out of the last state of an episode would cross the reset.
        valid = ~restarted
        previous_state, previous_action = state, action
        if (evaluate_every and step % evaluate_every == 0) or step == steps:
            curve.append(
                CurvePoint(
                    step,
                    reward_sum / window,
                    entropy_sum / window,
                    correcting_fraction(policy, task),
                )
            )
            reward_sum, entropy_sum, window = 0.0, 0.0, 0
    return curve


#: The published pursuit step sizes with θ alone as the state: what the study's curves start from
#: (NaturalActorCritic's defaults are the recipe's, whose extra state entries this task lacks).
PUBLISHED = dict(
    advantage_lr=0.025,
    actor_lr=0.002,
    weight_decay=0.01,
    feature_norm="none",
    zscore_horizon=0,
    eye_position_reference_m=0.0,
    reward_change_gain=0.0,
    # the study's robots are a minibatch: one update per step, the mean of theirs
    robot_updates="mean",
)


def run_seeds(
    seeds: Sequence[int],
    steps: int,
    num_robots: int = 32,
    config: PursuitTaskConfig | None = None,
    evaluations: int = 10,
    **policy_kwargs: object,
) -> list[list[CurvePoint]]:
    """Learning curves of fresh policies for several seeds: the published pursuit settings
    (``PUBLISHED``; the task gives θ alone) with ``policy_kwargs`` on top."""
    config = config or PursuitTaskConfig()
    curves = []
    for seed in seeds:
        task = SyntheticPursuit(num_robots, config, seed=seed)
        policy = NaturalActorCritic(
            state_dim=config.state_dim,
            num_scales=config.num_scales,
            seed=seed,
            **{**PUBLISHED, **policy_kwargs},
        )
        curves.append(train_on_synthetic_pursuit(policy, task, steps, max(steps // evaluations, 1)))
    return curves


def mean_curve(curves: list[list[CurvePoint]]) -> list[CurvePoint]:
    """Point-wise mean of learning curves taken at the same steps."""
    return [
        CurvePoint(points[0].step, *(sum(p[i] for p in points) / len(points) for i in (1, 2, 3)))
        for points in zip(*curves)
    ]


def plot_curves(curves: dict[str, list[CurvePoint]], path: str) -> None:
    """Reward and entropy of the sampling policy against steps, one line per setting."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 3, figsize=(13, 4.0))
    for label, curve in curves.items():
        steps = [p.step for p in curve]
        short = label.strip("{}").replace('"', "") or "defaults"
        axes[0].plot(steps, [p.reward for p in curve], label=short)
        axes[1].plot(steps, [p.entropy for p in curve])
        axes[2].plot(steps, [p.correcting for p in curve])
    for axis, title in zip(
        axes, ("mean reward −|offset| (sampling)", "policy entropy", "greedy correcting fraction")
    ):
        axis.set_title(title)
        axis.set_xlabel("update steps")
        axis.grid(alpha=0.3)
    figure.legend(loc="lower center", ncol=2, fontsize=8, frameon=False)
    figure.tight_layout(rect=(0, 0.15, 1, 1))
    figure.savefig(path, dpi=110)


def main(argv: Sequence[str] | None = None) -> None:
    import argparse
    import json

    parser = argparse.ArgumentParser(description="learning curves on the synthetic pursuit task")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--robots", type=int, default=32)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument(
        "--policy",
        type=json.loads,
        action="append",
        help='NaturalActorCritic keywords as JSON, e.g. {"feature_norm": "zscore"};'
        " repeat to compare settings",
    )
    parser.add_argument("--plot", help="write the learning curves to this image")
    arguments = parser.parse_args(argv)
    torch.set_num_threads(1)  # tiny tensors: extra threads only add synchronisation
    curves = {}
    for settings in arguments.policy or [{}]:
        label = json.dumps(settings)
        curves[label] = mean_curve(
            run_seeds(range(arguments.seeds), arguments.steps, arguments.robots, **settings)
        )
        print(label, flush=True)
        for point in curves[label]:
            print(
                f"step {point.step:6d}  reward {point.reward:+.3f}  entropy {point.entropy:.3f}"
                f"  correcting {point.correcting:.3f}",
                flush=True,
            )
    if arguments.plot:
        plot_curves(curves, arguments.plot)


if __name__ == "__main__":
    main()
