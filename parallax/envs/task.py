"""The lateral-pursuit task and `load` (paper §3.2 position set-up, Fig. 3; §4.1; §5).

One episode is one stimulus presentation. On reset the task draws a texture and a distance d
(with ``self.random`` only), captures the reference image I0 at l0 = 0 with pan 0, moves the
robot to l1 and resets the pan. At each lateral position l_p it gives t_h observations
(iterations 0 … t_h−1); each step turns the eye by the action, a pan increment in degrees from
A = {−0.2, −0.1, −0.05, 0, 0.05, 0.1, 0.2}. The step taken after iteration t_h−1 first applies
its increment, then picks the robot up and puts it down at l_{p+1} with the pan reset to 0
(paper default) or kept. The observation at iteration t_h−1 carries q_p, the pan of eq. (16);
the last one of l_r ends the episode, so an episode has r·t_h observations.

Beyond the paper, ``motion="continuous"``: the episode is one trial in which the body sweeps from
l0 to l_r (parallax.envs.sweep), moved on at every step while the eye turns; it has the sweep's
T observations, and the pans at the body offsets of L are read as it passes them.

Reward: −|α − α*| in degrees, a diagnostic (the learner's reward comes from the coder, eq. 6).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from dm_control.rl import control
from dm_control.suite import base
from dm_env import specs

from parallax.checks import default
from parallax.envs.hoap3 import Physics, check_distance
from parallax.envs.settings import EnvConfig, PerturbationConfig
from parallax.envs.stimuli import load_stimuli
from parallax.envs.sweep import body_offsets, sweep_iterations
from parallax.geometry import ACTION_SET_DEG


def distance_grid(distances: Sequence[float] | Mapping[str, float] | None) -> tuple[float, ...]:
    """Distances (m) from a list, a {start, stop, step} grid (stop included; env.distances,
    checked by parallax.config) or None (the schema's grid, the paper's 3.0, 3.1, …, 10.0 m)."""
    if distances is None:
        distances = default(EnvConfig, "distances")
    if isinstance(distances, Mapping):
        start, stop, step = (float(distances[k]) for k in ("start", "stop", "step"))
        count = int(math.floor((stop - start) / step + 1e-9)) + 1
        values = [round(start + i * step, 9) for i in range(count)]
    else:
        values = list(distances)
    if not values:
        raise ValueError("distances=[]: expected at least one distance")
    return tuple(check_distance(v) for v in values)


def check_lateral_positions(lateral_positions: Sequence[float]) -> tuple[float, ...]:
    """The list L: non-empty, finite, strictly increasing metres."""
    if isinstance(lateral_positions, (str, bytes)) or not isinstance(lateral_positions, Sequence):
        raise ValueError(f"lateral_positions={lateral_positions!r}: expected a list of metres")
    values = []
    for value in lateral_positions:
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float, np.integer, np.floating))
            or not math.isfinite(value)
        ):
            raise ValueError(
                f"lateral_positions={list(lateral_positions)!r}: {value!r} is not a finite number"
            )
        values.append(float(value))
    if not values:
        raise ValueError("lateral_positions=[]: expected at least one lateral position")
    if any(b <= a for a, b in zip(values, values[1:])):
        raise ValueError(f"lateral_positions={values!r}: must be strictly increasing")
    return tuple(values)


class LateralPursuitTask(base.Task):
    """Pursue the panel with the head pan while the body is put down at l1 … lr."""

    def __init__(
        self,
        lateral_positions: Sequence[float],
        trial_length: int,
        distances: tuple[float, ...],
        num_textures: int,
        pan_reset: bool = EnvConfig.pan_reset,
        max_pan_increment_deg: float = EnvConfig.max_pan_increment_deg,
        random: Any = None,
        initial_pan_jitter_deg: float = EnvConfig.initial_pan_jitter_deg,
        motion: str = EnvConfig.motion,
        sweep: Mapping[str, Any] = default(EnvConfig, "sweep"),
    ):
        super().__init__(random=random)
        self._continuous = motion == "continuous"
        self._sweep_speed, self._sweep_profile = float(sweep["speed_m"]), str(sweep["profile"])
        self._initial_pan_jitter = float(initial_pan_jitter_deg)
        self._pending_positions = check_lateral_positions(lateral_positions)
        self._episode_positions = self._pending_positions
        self._trial_length = int(trial_length)
        self._distances = distances
        self._num_textures = int(num_textures)
        self._pan_reset = bool(pan_reset)
        self._start_jitter_enabled = True
        self._max_increment = float(max_pan_increment_deg)
        self._forced_texture: int | None = None
        self._forced_distance: float | None = None
        self._physics: Physics | None = None
        self._reference: np.ndarray | None = None
        self._position_index = 0
        self._iteration = 0
        # a route the robot chooses as it goes (beyond the paper, §7): the next episode's first
        # position, and whether the running episode is one
        self._pending_route: float | None = None
        self._open_route = False
        self._offsets: np.ndarray | None = None  # the running sweep's x(t), when continuous

    # --- settings the trainer changes --------------------------------------------------------
    def attach(self, physics: Physics) -> None:
        """Give the task the physics it drives, so that perturbations apply at once."""
        self._physics = physics

    @property
    def num_textures(self) -> int:
        return self._num_textures

    @property
    def lateral_positions(self) -> tuple[float, ...]:
        """The list L of the next episode (the one most recently set)."""
        return self._pending_positions

    @property
    def episode_lateral_positions(self) -> tuple[float, ...]:
        """The list L of the running episode."""
        return self._episode_positions

    @property
    def continuous(self) -> bool:
        """Whether the body sweeps L in one trial (env.motion=continuous) instead of being set
        down at each position for t_h iterations."""
        return self._continuous

    @property
    def trials(self) -> int:
        """Trials per presentation of the next episode: one per position of L, or one sweep."""
        return 1 if self._continuous else len(self._pending_positions)

    @property
    def trial_length(self) -> int:
        """Iterations per trial: t_h, or the sweep's T (parallax.envs.sweep)."""
        if self._continuous:
            return sweep_iterations(self._pending_positions[-1], self._sweep_speed)
        return self._trial_length

    def _sweep_offsets(self, lateral_positions: Sequence[float]) -> np.ndarray:
        return body_offsets(lateral_positions[-1], self._sweep_speed, self._sweep_profile)

    @property
    def distances(self) -> tuple[float, ...]:
        return self._distances

    @property
    def action_set(self) -> tuple[float, ...]:
        return ACTION_SET_DEG

    def set_lateral_positions(self, lateral_positions: Sequence[float]) -> None:
        """Use the list L from the next reset on."""
        self._pending_positions = check_lateral_positions(lateral_positions)

    def set_next_stimulus(
        self, texture_index: int | None = None, distance: float | None = None
    ) -> None:
        """Force the next reset's texture and/or distance (one reset only; the random draws
        still happen)."""
        if texture_index is not None:
            if (
                isinstance(texture_index, bool)
                or not isinstance(texture_index, (int, np.integer))
                or not 0 <= texture_index < self._num_textures
            ):
                raise ValueError(
                    f"texture index {texture_index!r} is out of range: {self._num_textures} "
                    f"textures (0..{self._num_textures - 1})"
                )
            self._forced_texture = int(texture_index)
        if distance is not None:
            self._forced_distance = check_distance(distance)

    def start_route(self, lateral_m: float) -> None:
        """Make the next episode a route the robot chooses as it goes (beyond the paper, §7):
        it starts at ``lateral_m``, each next position comes from :meth:`visit_next`, and it
        ends when the robot stops (the environment never ends it: reset starts the next)."""
        self._pending_route = float(check_lateral_positions([lateral_m])[0])

    def visit_next(self, lateral_m: float) -> None:
        """On a route, at a trial's last iteration: the next trial is at ``lateral_m``."""
        if not self._open_route:
            raise RuntimeError("visit_next needs a route (start_route before the reset)")
        if self._iteration != self._trial_length - 1:
            raise RuntimeError(
                f"visit_next comes at a trial's last iteration ({self._trial_length - 1}), "
                f"not at {self._iteration}"
            )
        step = float(check_lateral_positions([lateral_m])[0])
        self._episode_positions = (*self._episode_positions[: self._position_index + 1], step)

    def random_state(self) -> tuple:
        """Where the task's random stream stands (its stimuli, distances and start pans): a
        checkpoint keeps it, and an evaluation that runs the same presentations twice puts it
        back (:meth:`set_random_state`)."""
        return self.random.get_state()

    def set_random_state(self, state: tuple) -> None:
        self.random.set_state(state)

    @property
    def start_jitter_enabled(self) -> bool:
        """Whether new trials start from a jittered pan (when a jitter is configured)."""
        return self._start_jitter_enabled

    def set_start_jitter(self, enabled: bool) -> None:
        """Let trials from the next one on start from the configured jitter (True) or from pan 0
        as in the paper (False); the trainer turns it off after
        ``train.start_jitter_presentations``."""
        if not isinstance(enabled, (bool, np.bool_)):
            raise ValueError(f"start jitter must be True or False, got {enabled!r}")
        self._start_jitter_enabled = bool(enabled)

    def set_perturbation(
        self,
        camera_rotation_deg: float | None = None,
        blur_sigma: float | None = None,
        rotation_axis: str | Sequence[float] | None = None,
    ) -> None:
        """Switch the §5 perturbations on or off, immediately (no recompile)."""
        if self._physics is None:
            raise RuntimeError(
                "the task is not attached to a physics; build it with parallax.envs.load"
            )
        self._physics.set_perturbation(
            camera_rotation_deg=camera_rotation_deg,
            blur_sigma=blur_sigma,
            rotation_axis=rotation_axis,
        )

    # --- dm_control Task interface -----------------------------------------------------------
    def initialize_episode(self, physics: Physics) -> None:
        # Both draws happen even when forced, so forcing leaves later episodes' draws unchanged.
        texture = int(self.random.randint(self._num_textures))
        distance = float(self._distances[self.random.randint(len(self._distances))])
        if self._forced_texture is not None:
            texture, self._forced_texture = self._forced_texture, None
        if self._forced_distance is not None:
            distance, self._forced_distance = self._forced_distance, None
        self._open_route = self._pending_route is not None
        if self._open_route:
            self._episode_positions, self._pending_route = (self._pending_route,), None
        else:
            self._episode_positions = self._pending_positions
        physics.set_stimulus(texture, distance)
        physics.set_lateral_position(0.0)
        physics.set_pan_deg(0.0)
        reference = physics.render_left_eye()
        reference.setflags(write=False)
        self._reference = reference
        self._offsets = self._sweep_offsets(self._episode_positions) if self._continuous else None
        first = 0.0 if self._continuous else self._episode_positions[0]
        physics.set_lateral_position(first)
        physics.set_pan_deg(self._trial_start_pan())
        self._position_index = 0
        self._iteration = 0

    def before_step(self, action: Any, physics: Physics) -> None:
        increment = self._pan_increment(action)
        physics.set_pan_deg(physics.pan_deg() + increment)
        if self._offsets is not None:  # the sweep: the body moves on while the eye turns
            self._iteration += 1
            physics.set_lateral_position(float(self._offsets[self._iteration]))
            return
        if self._iteration < self._trial_length - 1:
            self._iteration += 1
            return
        # Pick and place (§4.1): the next lateral position, a new trial.
        self._position_index += 1
        self._iteration = 0
        physics.set_lateral_position(self._episode_positions[self._position_index])
        if self._pan_reset:
            physics.set_pan_deg(self._trial_start_pan())

    def _trial_start_pan(self) -> float:
        """The pan a trial starts from: 0 (the paper), or uniform in ±initial_pan_jitter_deg so
        that the eye also learns from the far side of the target (beyond the paper). With no
        jitter nothing is drawn, so the random stream is the paper setting's, as it is once the
        jitter is switched off."""
        jitter = self._initial_pan_jitter
        if jitter == 0.0 or not self._start_jitter_enabled:
            return 0.0
        return float(self.random.uniform(-jitter, jitter))

    def _pan_increment(self, action: Any) -> float:
        value = np.asarray(action, dtype=np.float64)
        if value.size != 1 or not np.isfinite(value).all():
            raise ValueError(f"action={action!r}: expected one finite pan increment in degrees")
        increment = float(value.reshape(()))
        if abs(increment) > self._max_increment + 1e-9:
            raise ValueError(
                f"action={increment!r}°: a pan increment must lie within "
                f"±{self._max_increment}° (A = {ACTION_SET_DEG})"
            )
        return increment

    def get_observation(self, physics: Physics) -> OrderedDict:
        return OrderedDict(
            reference=self._reference,
            image=physics.render_left_eye(),
            pan=np.float64(physics.pan_deg()),
            target_pan=np.float64(physics.target_pan_deg()),
            distance=np.float64(physics.distance()),
            lateral_position=np.float64(physics.lateral_position()),
            position_index=np.int32(self._position_index),
            iteration=np.int32(self._iteration),
            texture_index=np.int32(physics.texture_index()),
        )

    def get_reward(self, physics: Physics) -> float:
        return -abs(physics.pan_deg() - physics.target_pan_deg())

    def get_termination(self, physics: Physics) -> float | None:
        if self._open_route:  # the robot ends a route by stopping
            return None
        if self._offsets is not None:
            return 1.0 if self._iteration == len(self._offsets) - 1 else None
        last_position = self._position_index == len(self._episode_positions) - 1
        if last_position and self._iteration == self._trial_length - 1:
            return 1.0
        return None

    def action_spec(self, physics: Physics) -> specs.BoundedArray:
        return specs.BoundedArray(
            shape=(),
            dtype=np.float64,
            minimum=-self._max_increment,
            maximum=self._max_increment,
            name="pan_increment_deg",
        )

    def observation_spec(self, physics: Physics) -> OrderedDict:
        size = physics.image_size
        image = specs.BoundedArray((size, size, 3), np.uint8, minimum=0, maximum=255)
        scalar = specs.Array((), np.float64)
        index = specs.Array((), np.int32)
        return OrderedDict(
            reference=image.replace(name="reference"),
            image=image.replace(name="image"),
            pan=scalar.replace(name="pan"),
            target_pan=scalar.replace(name="target_pan"),
            distance=scalar.replace(name="distance"),
            lateral_position=scalar.replace(name="lateral_position"),
            position_index=index.replace(name="position_index"),
            iteration=index.replace(name="iteration"),
            texture_index=index.replace(name="texture_index"),
        )


class PursuitEnvironment(control.Environment):
    """`control.Environment` whose ``close`` frees the eye's OpenGL context."""

    def close(self) -> None:
        self.physics.close_renderer()


def load(
    seed: int | None = None,
    lateral_positions: Sequence[float] = (0.05,),
    trial_length: int = EnvConfig.trial_length,
    distances: Sequence[float] | Mapping[str, float] | None = default(EnvConfig, "distances"),
    stimuli: Mapping[str, Any] | None = default(EnvConfig, "stimuli"),
    image_size: int = EnvConfig.image_size,
    fovea_px: int | None = EnvConfig.fovea_px,
    pan_reset: bool = EnvConfig.pan_reset,
    camera_rotation_deg: float = PerturbationConfig.camera_rotation_deg,
    rotation_axis: str | Sequence[float] = PerturbationConfig.rotation_axis,
    blur_sigma: float = PerturbationConfig.blur_sigma,
    max_pan_increment_deg: float = EnvConfig.max_pan_increment_deg,
    initial_pan_jitter_deg: float = EnvConfig.initial_pan_jitter_deg,
    motion: str = EnvConfig.motion,
    sweep: Mapping[str, Any] = default(EnvConfig, "sweep"),
) -> PursuitEnvironment:
    """The HOAP-3 lateral-pursuit world as a dm_control environment (see the module docstring);
    ``load(seed=0)`` is the default task, every default the schema's (EnvConfig,
    PerturbationConfig) but the lateral list, one position of 5 cm. The settings' ranges are
    checked by parallax.config; ``distances`` and ``stimuli`` None: the schema's too.

    ``stimuli``: {"source": "skimage" | "dir" | "procedural", "split": "train" | "heldout",
    "count": int | None, "dir": folder, "resolution": texels, "seed": int, "kind": "dead_leaves" |
    "pink_noise"}; the set is decoded once per process and shared.
    """
    lateral = check_lateral_positions(lateral_positions)
    grid = distance_grid(distances)
    texture_set = load_stimuli(stimuli)
    task = LateralPursuitTask(
        lateral,
        trial_length,
        grid,
        texture_set.count,
        pan_reset=pan_reset,
        max_pan_increment_deg=max_pan_increment_deg,
        random=seed,
        initial_pan_jitter_deg=initial_pan_jitter_deg,
        motion=motion,
        sweep=sweep,
    )
    physics = Physics.create(
        texture_set, image_size=image_size, max_distance_m=max(grid), fovea_px=fovea_px
    )
    physics.set_perturbation(
        camera_rotation_deg=camera_rotation_deg, blur_sigma=blur_sigma, rotation_axis=rotation_axis
    )
    task.attach(physics)
    return PursuitEnvironment(physics, task, time_limit=float("inf"))
