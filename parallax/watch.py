"""Watching one robot through a presentation: what the video panel draws (paper §3.2, Fig. 3).

A :class:`Watch` stands between :func:`parallax.loop.presentation` and its executor (the
:class:`parallax.lockstep.Lockstep` or :class:`parallax.executor.InOrder`) and changes nothing the
loop computes: each time robot 0's frames are handed to the loop, it notes the iteration's
lateral position, pan α and target pan α*, and at some iterations it also keeps robot 0's
left-eye image I(t) and a side camera's view of its world. :mod:`parallax.panel` draws those
:class:`Sample` s; :func:`read_distance` is the distance the robot reads at the presentation's
end (§3.5, or a planned route's estimate, §7), with the truth it is scored against.

Beyond the paper's pictures, :func:`walk_samples` shows an embodied robot's walk to the panel
(§7's second future work): the body stepped forward until its hand touches the panel, and put
back where it stood.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from parallax.envs.observation import Observation
from parallax.envs.walk import Walker
from parallax.parts import Parts
from parallax.presentation import Presentation
from parallax.readouts import PanReadout

#: Size (width, height) of the side camera's image in pixels.
SIDE_SIZE = (720, 360)


def side_camera(distance_m: float, lateral_m: float) -> mujoco.MjvCamera:
    """A free camera behind the robot's right shoulder that frames the robot at lateral
    position ``lateral_m`` and the panel ``distance_m`` ahead."""
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = (0.45 * distance_m, 0.25 - lateral_m, 0.65)
    camera.distance = 1.05 * distance_m + 1.0
    camera.azimuth = 32.0
    camera.elevation = -11.0
    return camera


@dataclass
class Sample:
    """Robot 0 at one iteration of a presentation (or, with ``walked_m``, of its walk)."""

    index: int  # the iteration's place in the presentation, from 0
    iteration: int  # its place in its trial, t = 0 … t_h − 1
    lateral_m: float  # the body's lateral position: l_p, or x(t) in a continuous sweep
    pan_deg: float  # α
    target_deg: float  # α*
    last_of_trial: bool  # the trial's last iteration, whose pan is q_p
    side: np.ndarray | None = None  # the side camera's view, at the iterations kept
    eye: np.ndarray | None = None  # the left eye's image I(t), at the iterations kept
    walked_m: float | None = None  # a walk's frame: how far the body has walked (m)

    @property
    def pictured(self) -> bool:
        return self.side is not None


class Watch:
    """The loop's executor, passed through, with robot 0's samples noted on the way; keeps the
    pictures of every ``every``-th iteration and of each trial's last. Pass :meth:`around` as
    :meth:`parallax.experiment.Experiment.run_presentation`'s ``watch``."""

    def __init__(
        self,
        world: Any,
        every: int = 1,
        side_size: tuple[int, int] = SIDE_SIZE,
        on_sample: Callable[[Sample], Any] | None = None,
    ):
        if every < 1:
            raise ValueError(f"every must be at least 1 iteration, got {every}")
        self.world, self.every, self.side_size = world, int(every), side_size
        self.on_sample = on_sample  # e.g. a progress bar's update
        self.samples: list[Sample] = []
        self.reference: np.ndarray | None = None  # I0
        self.camera: mujoco.MjvCamera | None = None
        self.run: Any = None

    @classmethod
    def spread(cls, world: Any, frames: int, side_size: tuple[int, int] = SIDE_SIZE) -> Watch:
        """A watch that keeps about ``frames`` pictures of a sweep of the world's list L (and
        those of each trial's end)."""
        task = world.task
        iterations = task.trials * task.trial_length
        return cls(world, every=max(1, -(-iterations // max(1, frames))), side_size=side_size)

    def around(self, run: Any) -> Watch:
        """This watch, in front of the executor ``run``."""
        self.run, self.samples, self.reference = run, [], None
        return self

    # --- the executor, passed through ---------------------------------------------------------
    @property
    def turns(self) -> list[slice]:
        return self.run.turns

    @property
    def seconds(self) -> dict[str, float]:
        return self.run.seconds

    def __enter__(self) -> Watch:
        self.run.__enter__()
        return self

    def __exit__(self, *error: Any) -> None:
        self.run.__exit__(*error)

    @property
    def trials(self) -> int:
        return self.run.trials

    def start_route(self, lateral_m: float) -> None:
        self.run.start_route(lateral_m)

    def visit_next(self, lateral_m: float) -> None:
        self.run.visit_next(lateral_m)

    def reset(self, learn: bool) -> None:
        self.run.reset(learn)

    def step(self, turn: int, pan_increments: Sequence[float]) -> None:
        self.run.step(turn, pan_increments)

    def frames(self, turn: int) -> Any:
        frames = self.run.frames(turn)
        if turn == 0:  # robot 0's world waits, as it is seen, until the turn's step
            self._note(frames.observations[0])
        return frames

    # --- what it notes ------------------------------------------------------------------------
    @property
    def physics(self) -> Any:
        return self.world.physics

    def _note(self, obs: Observation) -> None:
        task = self.world.task
        if self.reference is None:
            self.reference = np.array(obs.reference)
            lateral = task.lateral_positions
            middle = 0.5 * (lateral[0] + lateral[-1])
            self.camera = side_camera(obs.distance, middle)
        index = len(self.samples)
        last = obs.iteration == task.trial_length - 1
        sample = Sample(
            index=index,
            iteration=obs.iteration,
            lateral_m=obs.lateral_position,
            pan_deg=obs.pan,
            target_deg=obs.target_pan,
            last_of_trial=last,
        )
        if index % self.every == 0 or last:
            sample.side = self.physics.render_view(self.camera, *self.side_size)
            sample.eye = np.array(obs.image)
        self.samples.append(sample)
        if self.on_sample is not None:
            self.on_sample(sample)


def read_distance(
    parts: Parts, pres: Presentation, readout: type[PanReadout], truths: Any = None
) -> tuple[float, float] | None:
    """Robot 0's distance read from the presentation's s (a planned route: the planner's
    estimate from the positions it visited) and the truth it is scored against (``truths``, a
    target source's ``truths`` (parallax.distance.targets); default: the panel's distance);
    None while the learner that would read it has not learnt yet."""
    pans = pres.read(readout)[0]
    distance = float(pres.distances[0])
    truth = distance if truths is None else float(np.asarray(truths([distance])).reshape(-1)[0])
    if pres.route is not None:
        if parts.planner is None or not parts.planner.is_ready:
            return None
        return parts.planner.estimate(pres.route, pans[pres.route]), truth
    if not parts.distance.is_ready:
        return None
    read = float(np.asarray(parts.distance.predict(pans[None, :]), dtype=np.float64).reshape(-1)[0])
    return read, truth


def walk_samples(watch: Watch, frames: int = 12, step_m: float = 0.02) -> list[Sample]:
    """The body walked from l0 straight at the panel until its hand touches it, in ``frames``
    pictures; the body is put back as it stood (the walk draws no random numbers)."""
    physics = watch.physics
    lateral, forward = physics.lateral_position(), physics.forward_position()
    last = watch.samples[-1]
    pictures: list[Sample] = []
    try:
        physics.set_lateral_position(0.0)
        reach = 0.0
        while Walker.gap_m(physics) > 0.0 and reach < physics.distance():
            reach += step_m
            physics.set_forward_position(forward + reach)
        for k, ahead in enumerate(np.linspace(0.0, reach, frames)):
            physics.set_forward_position(forward + float(ahead))
            physics.forward()
            pictures.append(
                Sample(
                    index=last.index + 1 + k,
                    iteration=last.iteration,
                    lateral_m=0.0,
                    pan_deg=last.pan_deg,
                    target_deg=last.target_deg,
                    last_of_trial=False,
                    side=physics.render_view(watch.camera, *watch.side_size),
                    eye=physics.render_left_eye(),
                    walked_m=float(ahead),
                )
            )
    finally:
        physics.set_forward_position(forward)
        physics.set_lateral_position(lateral)
    return pictures
