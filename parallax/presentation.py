"""What B robots did in one stimulus presentation (paper §3.2, Fig. 3), gathered as it runs.

:class:`Tally` collects, iteration by iteration, what :func:`parallax.loop.presentation` reports:
the positions visited, q_p (the pan at each trial's last iteration) and α* there, every trial's
pans and rewards (which a pan readout, :mod:`parallax.readouts`, reads s from), the coder's mean
reward and errors; :class:`Presentation` is the result, with the policy's mean statistics.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from parallax.coding import CoderOutput
from parallax.envs.observation import Observation
from parallax.metrics import position_label

if TYPE_CHECKING:
    from parallax.executor import Frames


class Trials(NamedTuple):
    """Each trial's iterations: (B, r, t_h) pans (deg) and the coder's rewards (NaN: not yet,
    or a position not visited)."""

    pans: np.ndarray
    rewards: np.ndarray


@dataclass
class Presentation:
    """What B robots did during one stimulus presentation."""

    lateral_positions: list[float]  # the list L used (metres)
    pans: np.ndarray  # (B, r) pan at the last iteration of each trial, q_p (deg)
    targets: np.ndarray  # (B, r) target pan α* at that iteration (deg)
    # every trial's pans and rewards, which a pan readout reads s from; None when the body
    # sweeps L in one trial (env.motion=continuous), whose s is ``pans``, read as it passes l_p
    trials: Trials | None
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
    # beyond the paper (env.motion=continuous): the eye's mean |α − α*| over the sweep's
    # iterations and the retinal slip, the mean |Δ(α* − α)| per iteration (deg); None otherwise
    motion: dict[str, float] | None = None
    # seconds the loop's thread spent waiting in the lockstep (parallax.lockstep.WAITS): for
    # frames, for the dictionary step, encoding; the rest of its time is the policy's turn
    waits: dict[str, float] = field(default_factory=dict)

    @property
    def labels(self) -> list[str]:
        return [position_label(l) for l in self.lateral_positions]

    def read(self, readout) -> np.ndarray:  # type: ignore[no-untyped-def]
        """(B, r) s as ``readout`` (a :class:`parallax.readouts.PanReadout`) reads it."""
        return self.pans if self.trials is None else readout.read(*self.trials)


class Tally:
    """What one presentation reports (:class:`Presentation`), gathered iteration by iteration."""

    def __init__(
        self,
        robots: int,
        lateral: list[float],
        trial_length: int,
        routed: bool = False,
        continuous: bool = False,
    ) -> None:
        self.lateral, self.trial_length = lateral, trial_length
        shape = (robots, len(lateral))
        # the body sweeping L in one trial: q_p is read as it passes l_p, between the iterations
        # either side (each robot's last body offset, pan and α*), and the pursuit is tallied
        self.sweep = _SweepTally(robots, lateral) if continuous else None
        # on a chosen route the positions never visited keep NaN
        unseen = np.nan if routed else 0.0
        self.pans, self.targets, self.start_pans = (np.full(shape, unseen) for _ in range(3))
        every = (*shape, trial_length)
        self.trials = Trials(np.full(every, unseen), np.full(every, np.nan))
        self.routed, self.visited, self.position = routed, [], 0  # the positions of L visited
        self.observations: list[Observation | None] = [None] * robots  # each robot's latest
        # sums over robots and iterations, and the robot-encodings they add up
        self.reward_sum, self.error_sums, self.encodings = 0.0, {}, 0

    def visit(self, p: int) -> None:
        """A trial at position ``p`` of L begins."""
        self.visited.append(p)
        self.position = p

    def seen(self, frames: Frames) -> None:
        """A turn's frames, at the position of L visited now."""
        self.observations[frames.robots] = frames.observations
        out, p = frames.output, self.position
        self.encoded(frames.observations, out, frames.pans, frames.rewards, p, frames.robots)

    def so_far(self) -> Presentation:
        """The record as it stands, for a route to choose where next."""
        return self.presentation(keep_view=False)

    def encoded(
        self,
        obs: list[Observation],
        out: CoderOutput,
        pans: np.ndarray,
        rewards: np.ndarray,
        p: int,
        robots: slice = slice(None),
    ) -> None:
        """The coder's output ``out`` (rewards in float64) for the images of ``robots`` (all by
        default) seen at ``pans``, at position ``p`` of L."""
        iteration = obs[0].iteration
        self.reward_sum += float(out.reward.sum())
        for scale, e in out.errors.items():
            self.error_sums[scale] = self.error_sums.get(scale, 0.0) + float(e.sum())
        self.encodings += len(rewards)
        if self.sweep is not None:
            self.sweep.passed(obs, pans, robots, self.pans, self.targets)
            if iteration == 0:
                self.start_pans[robots] = pans[:, None]
            return
        if iteration == 0:
            self.start_pans[robots, p] = pans
        self.trials.pans[robots, p, iteration] = pans
        self.trials.rewards[robots, p, iteration] = rewards
        if iteration == self.trial_length - 1:  # q_p, and α* there
            self.pans[robots, p] = pans
            self.targets[robots, p] = [o.target_pan for o in obs]

    def presentation(
        self, keep_view: bool, policy_stats: dict[str, float] | None = None
    ) -> Presentation:
        """The record, from the tally and the last observations (before every robot's first,
        the distances and textures are unknown, NaN and −1)."""
        obs = self.observations if all(o is not None for o in self.observations) else []
        view = None
        if keep_view:
            view = np.concatenate([obs[0].reference, obs[0].image], axis=1)
        encodings = max(self.encodings, 1)
        robots = self.pans.shape[0]
        return Presentation(
            lateral_positions=self.lateral,
            pans=self.pans,
            targets=self.targets,
            trials=None if self.sweep is not None else self.trials,
            distances=np.array([o.distance for o in obs] if obs else [np.nan] * robots),
            textures=np.array([o.texture_index for o in obs] if obs else [-1] * robots),
            steps=self.encodings // robots,
            reward=self.reward_sum / encodings,
            errors={k: v / encodings for k, v in self.error_sums.items()},
            policy_stats=dict(policy_stats or {}),
            last_view=view,
            start_pans=self.start_pans,
            route=list(self.visited) if self.routed else None,
            motion=None if self.sweep is None else self.sweep.summary(),
        )


class _SweepTally:
    """q_p and α* as the body passes each l_p of a continuous sweep (linear between the two
    iterations either side of it), and the pursuit's tracking error and retinal slip."""

    def __init__(self, robots: int, lateral: list[float]) -> None:
        self.lateral = np.asarray(lateral, dtype=np.float64)
        self.last = np.full((robots, 3), np.nan)  # each robot's last body offset, pan and α*
        self.tracking_sum = self.slip_sum = 0.0
        self.tracked = self.slips = 0

    def passed(
        self,
        obs: list[Observation],
        pans: np.ndarray,
        robots: slice,
        q: np.ndarray,
        targets: np.ndarray,
    ) -> None:
        """The turn ``robots`` saw ``obs`` at ``pans``: fill q_p and α* (``q``, ``targets``, (B, r))
        at every l_p passed since its last iteration (at the first: every l_p ≤ x(0))."""
        now = np.array([[o.lateral_position, pan, o.target_pan] for o, pan in zip(obs, pans)])
        before = self.last[robots]
        self.tracking_sum += float(np.abs(now[:, 2] - now[:, 1]).sum())
        self.tracked += len(now)
        moved = ~np.isnan(before[:, 0])
        # the panel's image moves on the retina by the change of the gaze's error α* − α
        slip = (now[moved, 2] - now[moved, 1]) - (before[moved, 2] - before[moved, 1])
        self.slip_sum += float(np.abs(slip).sum())
        self.slips += int(moved.sum())
        for i, b in enumerate(range(*robots.indices(q.shape[0]))):
            start = before[i] if moved[i] else now[i]
            lower = start[0] if moved[i] else -np.inf
            for p in np.flatnonzero((self.lateral > lower) & (self.lateral <= now[i, 0])):
                span = now[i, 0] - start[0]
                share = (self.lateral[p] - start[0]) / span if span > 0 else 1.0
                q[b, p] = start[1] + share * (now[i, 1] - start[1])
                targets[b, p] = start[2] + share * (now[i, 2] - start[2])
        self.last[robots] = now

    def summary(self) -> dict[str, float]:
        return {
            "tracking_error_deg": self.tracking_sum / max(self.tracked, 1),
            "retinal_slip_deg": self.slip_sum / max(self.slips, 1),
        }
