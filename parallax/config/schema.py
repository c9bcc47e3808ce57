"""The structured-config schema: every setting of `parallax-train`, its type and its one default.

One dataclass per config group, registered in Hydra's ConfigStore (:func:`register`): the files
in conf/<group>/ extend their group's ``schema`` node (Hydra's "static schema with many
configs") and hold only what makes that choice differ, so Hydra checks every value's type and
the defaults live in the dataclasses alone. Each part's nodes are in its ``settings.py``, beside
their checks (parallax.envs.settings, parallax.coding.settings, parallax.policy.settings,
parallax.distance.settings); the run's own (the lateral list, the schedule, the metrics) and the
whole are here. The defaults are our recipe: the paper's model (section and
equation numbers below are the paper's) with the settings marked "beyond the paper", which
docs/improvements.md explains; conf/experiment/paper_*.yaml switch those off again. Values known
only at run time (sizes, seeds the trainer derives) are ``MISSING`` (``???``) and filled before
instantiation. :mod:`parallax.config.validate` runs every part's checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from parallax.checks import ROBOT_UPDATES, default
from parallax.coding.settings import CoderConfig, ScaleSpecConfig
from parallax.distance.settings import (
    DistanceConfig,
    LevenbergMarquardtConfig,
    MovementConfig,
    OdometryConfig,
    SensitivityConfig,
)
from parallax.envs.settings import (
    DistanceGridConfig,
    EnvConfig,
    PerturbationConfig,
    StimuliConfig,
    SweepConfig,
    WalkConfig,
)
from parallax.policy.settings import PolicyConfig

#: The paper's lateral list for multiple positions 5–20 cm in 1 cm steps (§4.2.1), in metres.
LATERAL_5_20_M = [round(0.05 + 0.01 * i, 2) for i in range(16)]
#: The name under which each group's schema node is stored (conf/<group>/ files extend it).
SCHEMA_NODE = "schema"


# --- the lateral list (curriculum/) ----------------------------------------------------------
@dataclass
class CurriculumConfig:
    """The lateral list L (§3.2, Fig. 3) and, beyond the paper, a staged widening of it."""

    #: Reported in summaries.
    name: str = "multi_5_20"
    #: L in metres, strictly increasing (§4.2.1: single positions 5–20 cm, or 5–10 / 5–20 cm in
    #: 1 cm steps).
    lateral_positions: list[float] = field(default_factory=lambda: list(LATERAL_5_20_M))
    #: Beyond the paper: lists the trials move through, each a subset of L, the last equal to L;
    #: the next one starts once every position of the current one has an eye-movement MAE below
    #: ``advance_below_deg`` over at least ``min_trials`` trials. null: L from the start.
    stages: list[list[float]] | None = None
    #: Eye-movement MAE (degrees, eq. 16) below which a stage is passed.
    advance_below_deg: float = 0.25
    #: Trials each position of a stage needs before the stage can be passed.
    min_trials: int = 200


# --- the run (top level) ---------------------------------------------------------------------
@dataclass
class TrainConfig:
    #: Stimulus presentations per robot; one presentation is r·t_h iterations (Fig. 3).
    presentations: int = 3000
    #: Presentations between checkpoints (one is also written at the end).
    checkpoint_every: int = 25
    #: Presentations between TensorBoard images (dictionary atoms, left eye beside I0).
    image_every: int = 50
    #: Torch intra-op threads (0: torch's default); these matrices are small, and one thread
    #: does not wait for a second one on a shared CPU.
    threads: int = 1
    #: Beyond the paper: with env.initial_pan_jitter_deg > 0, only the first this many
    #: presentations start their trials from a jittered pan, so that the last trials (Tables
    #: 2–3) are measured from pan 0 as in the paper. null: every presentation.
    start_jitter_presentations: int | None = None
    #: How a trial's pan becomes its component of s, one of parallax/readouts/: last, its last
    #: pan (the paper's q_p, eq. 16) | best_reward (beyond the paper), the pan whose image the
    #: coder encoded best in that trial, which a runaway at the trial's end does not spoil.
    distance_readout: str = "best_reward"
    #: Which checkpoint a resumed run continues from: latest (checkpoint.pt) | previous
    #: (checkpoint_previous.pt, the one written before it), for a latest one that is damaged.
    resume_from: str = "latest"
    #: The critic's scale, mean |v·φ| over a presentation, above which the run says once that
    #: its critic is diverging (parallax/health.py: with rewards in [−2, 0] a critic that fits
    #: its TD targets stays within 2/(1 − ξ), 100 at ξ = 0.98).
    critic_scale_warning: float = 100.0
    #: Presentations in a row with numbers that are not finite (an update the policy skipped, a
    #: statistic that overflowed, a distance fit stopped on a non-finite Jacobian) after which
    #: the run stops, keeping its last good checkpoint; null: say so and run on (a study of
    #: divergence).
    stop_after_non_finite: int | None = 3


@dataclass
class MetricsConfig:
    #: Trials in the sliding window of the eye-movement MAE, eq. (16).
    mae_window: int = 1000
    #: Trials in the "last 100 trials average (variance)" of Tables 2–3, and in the recent MAE
    #: logged beside eq. (16)'s window.
    summary_trials: int = 100
    #: Online distance predictions (made before each new s is learnt) kept for the error per
    #: range (Tables 4–5).
    distance_window: int = 500


@dataclass
class Config:
    """The whole run: parallax-train's composed configuration."""

    env: EnvConfig = field(default_factory=EnvConfig)
    coder: CoderConfig = field(default_factory=CoderConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    distance: DistanceConfig = field(default_factory=DistanceConfig)
    curriculum: CurriculumConfig = field(default_factory=CurriculumConfig)
    perturbation: PerturbationConfig = field(default_factory=PerturbationConfig)
    movement: MovementConfig = field(default_factory=MovementConfig)
    #: The run's seed; every component's seed is derived from it (parallax.parts.Seeds).
    seed: int = 0
    #: cpu | cuda | cuda:<n>: where the coder, policy and distance learner live (the world
    #: renders through MuJoCo and hands its frames over in host memory).
    device: str = "cpu"
    #: Continue from the checkpoint in the run directory if there is one.
    resume: bool = True
    train: TrainConfig = field(default_factory=TrainConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)


#: Group name → schema node; conf/<group>/*.yaml extend ``<group>/schema``.
GROUPS: dict[str, type] = {
    "env": EnvConfig,
    "coder": CoderConfig,
    "policy": PolicyConfig,
    "distance": DistanceConfig,
    "curriculum": CurriculumConfig,
    "perturbation": PerturbationConfig,
}


def register() -> None:
    """Store the schema in Hydra's ConfigStore: the top level as ``schema`` (conf/config.yaml's
    first default) and each group's node as ``<group>/schema``. Idempotent."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    store.store(name=SCHEMA_NODE, node=Config)
    for group, node in GROUPS.items():
        store.store(group=group, name=SCHEMA_NODE, node=node)


#: What this module hands on from the parts' settings (parallax.config re-exports them).
__all__ = [
    "GROUPS",
    "LATERAL_5_20_M",
    "ROBOT_UPDATES",
    "SCHEMA_NODE",
    "CoderConfig",
    "Config",
    "CurriculumConfig",
    "DistanceConfig",
    "DistanceGridConfig",
    "EnvConfig",
    "LevenbergMarquardtConfig",
    "MetricsConfig",
    "MovementConfig",
    "OdometryConfig",
    "PerturbationConfig",
    "PolicyConfig",
    "ScaleSpecConfig",
    "SensitivityConfig",
    "StimuliConfig",
    "SweepConfig",
    "TrainConfig",
    "WalkConfig",
    "default",
    "register",
]
