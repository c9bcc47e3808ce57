"""The body's walk to the stimulus: beyond the paper, for its second future work (§7).

The paper's distance learner is told the true distance by a supervisor (§3.5). Here the robot
can find out for itself how far the panel is, in its own body's units: after the lateral sweep
it stands at l0, walks straight at the panel until its left hand touches it, counts its strides,
and steps back to where it stood. Its odometry is that count times the stride length it believes
it has (parallax.distance.targets.OdometryTargets).

The walk is kinematic, as the sweep's sideways steps are (the body is a mocap body put down
where the stride ends); each stride's true length is the body's stride (``stride_m``, times a
growth factor) times 1 + slip·N(0, 1). The touch is MuJoCo's: the signed distance between the
hand's geom and the panel's (``mj_geomDistance``) reaching zero, checked after every stride. The
stride that ends in touch is taken again in ``substeps`` equal parts, so that the count also says
how far into it the hand met the panel. The scene's distance d is never read.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from parallax.envs.hoap3 import Physics
from parallax.envs.settings import WalkConfig

#: The body part that touches the panel, and the panel.
HAND_GEOM = "hand_left"
PANEL_GEOM = "panel"
#: The signed distance is computed up to this far (m); beyond it MuJoCo reports this value.
QUERY_RANGE_M = 100.0


@dataclass(frozen=True)
class Walk:
    """One walk to the panel: what the robot counted, and (for diagnostics only) the truth."""

    #: Strides counted until the touch; the last one as the part of it taken (1/substeps steps).
    strides: float
    #: The distance the body actually moved (m); the robot does not know it.
    travelled_m: float


class Walker:
    """Walks one robot's body to the panel and back; its slip noise has its own random stream,
    so walking never changes what the eye sees or learns. The body is env.walk's (whose ranges
    parallax.config checks); from presentation ``growth_start`` on (env.walk.
    growth_start_fraction of the run; None: never) its stride is grown (:meth:`at_presentation`)."""

    def __init__(
        self,
        *,
        seed: int,
        stride_m: float = WalkConfig.stride_m,
        stride_slip: float = WalkConfig.stride_slip,
        substeps: int = WalkConfig.substeps,
        growth_factor: float = WalkConfig.growth_factor,
        growth_start: int | None = None,
    ) -> None:
        self.stride_m = float(stride_m)
        self.stride_slip = float(stride_slip)
        self.substeps = int(substeps)
        self.growth_factor = float(growth_factor)
        self.growth_start = growth_start
        self.grown = False
        self.random = np.random.RandomState(int(seed) % 2**32)

    def at_presentation(self, presentation: int) -> None:
        """Presentation ``presentation`` (0-based) is next: the body grown from the growth
        spurt's on, as it was before it."""
        self.grown = self.growth_start is not None and presentation >= self.growth_start

    @property
    def true_stride_m(self) -> float:
        """The body's stride now (after a growth spurt, the grown one)."""
        return self.stride_m * (self.growth_factor if self.grown else 1.0)

    def decide(self, fraction: float) -> bool:
        """Whether this presentation ends with a walk (drawn even when ``fraction`` is 1, so the
        slip draws do not depend on it)."""
        return bool(self.random.random_sample() < fraction)

    @staticmethod
    def gap_m(physics: Physics) -> float:
        """MuJoCo's signed distance from the hand to the panel (m): ≤ 0 is a touch."""
        model, data = physics.model.ptr, physics.data.ptr
        hand = physics.model.name2id(HAND_GEOM, "geom")
        panel = physics.model.name2id(PANEL_GEOM, "geom")
        return float(mujoco.mj_geomDistance(model, data, hand, panel, QUERY_RANGE_M, None))

    def reach_strides(self, physics: Physics, distance_m: float | None = None) -> float:
        """How many of its present true strides the body needs from l0 to touch the panel (or the
        panel put at ``distance_m``), with no slip: the yardstick of the odometry's errors (never
        shown to the robot)."""
        if distance_m is None or float(distance_m) == physics.distance():
            gap = self._at_l0(physics, lambda: self.gap_m(physics))
        else:  # the panel moved there and back: the same bits wherever it stood
            texture, distance = physics.texture_index(), physics.distance()
            physics.set_stimulus(texture, float(distance_m))
            try:
                gap = self._at_l0(physics, lambda: self.gap_m(physics))
            finally:
                physics.set_stimulus(texture, distance)
        return gap / self.true_stride_m

    def walk(self, physics: Physics) -> Walk:
        """Walk from l0 until the hand touches the panel; the body is put back as it was."""
        return self._at_l0(physics, lambda: self._walk(physics))

    def _walk(self, physics: Physics) -> Walk:
        start = physics.forward_position()
        position, strides = start, 0
        limit = int(QUERY_RANGE_M / (self.true_stride_m * (1.0 - self.stride_slip)))
        while True:
            stride = self.true_stride_m * (1.0 + self.stride_slip * self.random.standard_normal())
            physics.set_forward_position(position + stride)
            if self.gap_m(physics) <= 0.0:  # touched during this stride: take it again, slowly
                for part in range(1, self.substeps + 1):
                    physics.set_forward_position(position + stride * part / self.substeps)
                    if self.gap_m(physics) <= 0.0:
                        break
                travelled = physics.forward_position() - start
                return Walk(strides=strides + part / self.substeps, travelled_m=travelled)
            position, strides = position + stride, strides + 1
            if strides > limit:
                raise RuntimeError(f"the walk did not reach the panel in {strides} strides")

    @staticmethod
    def _at_l0(physics: Physics, action):  # type: ignore[no-untyped-def]
        """Run ``action`` with the body at l0 and its sweep pose, then restore the body."""
        lateral, forward = physics.lateral_position(), physics.forward_position()
        physics.set_lateral_position(0.0)
        try:
            return action()
        finally:
            physics.set_forward_position(forward)
            physics.set_lateral_position(lateral)  # mj_forward: the state as it was

    def state_dict(self) -> dict:
        return {"random": self.random.get_state(), "grown": self.grown}

    def load_state_dict(self, state: dict) -> None:
        self.random.set_state(state["random"])
        self.grown = bool(state["grown"])


def walk_robots(
    physics: Sequence[Physics], walkers: Sequence[Walker], fraction: float
) -> tuple[list[float | None], list[float]]:
    """Each robot decides whether to walk (probability ``fraction``) and, if so, walks: the
    strides counted (None for a robot that stayed), and every robot's slip-free stride count to
    the panel, the yardstick."""
    counted: list[float | None] = []
    for body, walker in zip(physics, walkers, strict=True):
        counted.append(walker.walk(body).strides if walker.decide(fraction) else None)
    return counted, [walker.reach_strides(body) for body, walker in zip(physics, walkers)]
