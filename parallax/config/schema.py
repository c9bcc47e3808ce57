"""The structured-config schema: every setting of `parallax-train`, its type and its one default.

One dataclass per config group, registered in Hydra's ConfigStore (:func:`register`): the files
in conf/<group>/ extend their group's ``schema`` node (Hydra's "static schema with many
configs") and hold only what makes that choice differ, so Hydra checks every value's type and
the defaults live here alone. The defaults are our recipe: the paper's model (section and
equation numbers below are the paper's) with the settings marked "beyond the paper", which
docs/improvements.md explains; conf/experiment/paper_*.yaml switch those off again. Values known
only at run time (sizes, seeds the trainer derives) are ``MISSING`` (``???``) and filled before
instantiation. Ranges and cross-field rules are checked by :mod:`parallax.config.validate`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from omegaconf import MISSING

from parallax.geometry import ACTION_SET_DEG

#: The paper's lateral list for multiple positions 5–20 cm in 1 cm steps (§4.2.1), in metres.
LATERAL_5_20_M = [round(0.05 + 0.01 * i, 2) for i in range(16)]
#: The name under which each group's schema node is stored (conf/<group>/ files extend it).
SCHEMA_NODE = "schema"
#: How B robots in lockstep teach the dictionaries (coder.robot_updates) and the policy
#: (policy.robot_updates): each, every robot's update applied as a step of its own | mean, one
#: step, the mean of the robots' updates. Either is the paper's single robot at env.robots=1.
ROBOT_UPDATES = ("each", "mean")
#: With env.fovea_px, the image outside the fovea is rendered at 1/this of the resolution.
PERIPHERY_SUBSAMPLE = 4


# --- the world (env/) ------------------------------------------------------------------------
@dataclass
class DistanceGridConfig:
    """Panel distances drawn per presentation, metres: start, start + step, …, stop (§4.1)."""

    #: Nearest panel distance (m).
    start: float = 3.0
    #: Farthest panel distance (m).
    stop: float = 10.0
    #: Spacing of the distances (m).
    step: float = 0.1


@dataclass
class StimuliConfig:
    """The panel's textures, "a set of 100 different images" (§4.1); parallax.envs.stimuli."""

    #: skimage: crops of the photographs scikit-image ships | dir: your own images (``dir``) |
    #: procedural: generated textures (``kind``), an ablation.
    source: str = "skimage"
    #: train | heldout: held-out crops come from other photographs (a folder is used whole).
    split: str = "train"
    #: Number of textures; null: 120 train / 40 held-out, or every readable image of ``dir``.
    count: int | None = None
    #: Folder of your own images; setting it switches ``source`` to dir.
    dir: str | None = None
    #: Texture side in texels.
    resolution: int = 256
    #: Seed of the crop positions / procedural textures (not of the presentation order).
    seed: int = 0
    #: Procedural kind: dead_leaves | pink_noise.
    kind: str = "dead_leaves"


@dataclass
class SweepConfig:
    """Beyond the paper: the body's continuous sweep from l0 to the end of L in one trial
    (``env.motion=continuous``; parallax.envs.sweep)."""

    #: Mean lateral speed, metres per iteration (0.002: 5–20 cm in 101 iterations).
    speed_m: float = 0.002
    #: constant | smooth: a minimum-jerk path, still at both ends (peak speed 1.875× the mean).
    profile: str = "constant"


@dataclass
class WalkConfig:
    """Beyond the paper (its second future work, §7): the body's walk straight to the panel after
    a presentation's lateral sweep, until its left hand touches it (parallax.envs.walk). Only
    runs with distance.targets=odometry walk. These are the body's true values; what the robot
    believes its stride to be is distance.odometry.nominal_stride_m."""

    #: The body's true stride length (m).
    stride_m: float = 0.05
    #: Each stride's length varies by this fraction (sd of a Gaussian factor 1 + slip·N(0, 1)).
    stride_slip: float = 0.0
    #: The stride that ends in touch is retaken in this many equal parts, so the robot also knows
    #: how far into its last stride the touch came (odometry resolution stride_m / substeps).
    substeps: int = 10
    #: A growth spurt: the true stride is multiplied by this from ``growth_start_fraction`` of
    #: train.presentations on, while the robot keeps its nominal stride (1: no spurt).
    growth_factor: float = 1.0
    #: Fraction of train.presentations after which the spurt happens; null: never.
    growth_start_fraction: float | None = None


@dataclass
class EnvConfig:
    """The world (§4.1): HOAP-3-like humanoid, textured panel, still background, in MuJoCo.

    The keyword arguments of ``parallax.envs.load``, which reads its defaults here (``robots``,
    ``robots_per_turn`` and ``walk`` aside: parallax.parts.NOT_THE_WORLDS);
    the lateral list L comes from ``curriculum`` and the perturbation from ``perturbation``.
    """

    #: Side of the square left-eye image in pixels; the focal length stays 531 px (Table 1).
    image_size: int = 256
    #: null: every pixel of the eye image is rendered at full resolution. A size (the fine
    #: scale's window, 150): only what the retina reads at full resolution, the central square of
    #: this many pixels, and the rest of the image rendered at 1/4 of the resolution and
    #: enlarged, which the coarse scale's ×8 pyramid reads (fewer pixels to rasterise; it changes
    #: the images, so it is off by default; docs/performance.md).
    fovea_px: int | None = None
    #: t_h, iterations (eye movements) per lateral position (§4.1).
    trial_length: int = 30
    #: The paper's distances 3.0, 3.1, …, 10.0 m (§4.1).
    distances: DistanceGridConfig = field(default_factory=DistanceGridConfig)
    #: At each new lateral position: true turns the pan back to 0 (§3.2), false keeps it.
    pan_reset: bool = True
    #: Beyond the paper: each trial starts from a pan drawn uniformly in ±this many degrees
    #: instead of 0, so the eye also learns from the far side of the target (0: the paper, and
    #: the recipe at multiple lateral positions; the single-position files use 2).
    initial_pan_jitter_deg: float = 0.0
    #: Largest pan increment the world accepts, degrees (A = {±0.2, ±0.1, ±0.05, 0}, §3.4).
    max_pan_increment_deg: float = 0.2
    #: pick_and_place: the body is set down at each position of L for t_h iterations (§4.1) |
    #: continuous: it sweeps from l0 to the end of L in one trial while the eye acts (``sweep``;
    #: beyond the paper), and q_p is the pan as it passes l_p.
    motion: str = "pick_and_place"
    sweep: SweepConfig = field(default_factory=SweepConfig)
    stimuli: StimuliConfig = field(default_factory=StimuliConfig)
    #: B robots in lockstep, each with its own stimulus, distance and pan; one coder and policy
    #: call serves all of them (beyond the paper, for speed; B = 1 is the paper's single robot).
    robots: int = 1
    #: B robots take their turns in groups of this many (0: all B in one turn): each turn's
    #: policy update and action come after the previous turn's, and its worlds render while the
    #: later turns are encoded and act (beyond the paper; B ≤ this is one turn, the paper's order).
    robots_per_turn: int = 4
    walk: WalkConfig = field(default_factory=WalkConfig)


# --- the sensory coder (coder/) --------------------------------------------------------------
@dataclass
class ScaleSpecConfig:
    """One scale of §3.3 / Fig. 5: centre window, Gaussian-pyramid sub-sampling P_s, patch side
    P_l and the patches' stride, all in pixels."""

    #: Side of the centre window cut from the eye image (px).
    window: int = MISSING
    #: P_s, the Gaussian pyramid's sub-sampling factor of the window.
    subsample: int = MISSING
    #: P_l, the side of a square patch of the sub-sampled window (px).
    patch: int = MISSING
    #: Step between neighbouring patches (px of the sub-sampled window).
    stride: int = MISSING


def _paper_scales() -> dict[str, ScaleSpecConfig]:
    # §3.3: coarse 250 px sub-sampled ×8 (32×32 px → 529 patches at stride 1), fine 150 px
    # sub-sampled ×2 (75×75 px → 289 patches at stride 4); 10×10 px patches
    return {
        "coarse": ScaleSpecConfig(window=250, subsample=8, patch=10, stride=1),
        "fine": ScaleSpecConfig(window=150, subsample=2, patch=10, stride=4),
    }


@dataclass
class CoderConfig:
    """Sensory coding (§3.3, eqs. 1–6): matching pursuit on a learned binocular dictionary per
    scale; the state θ = [θ^C; θ^F] (eq. 5) and the reward R = −(e^C + e^F) (eq. 6)."""

    _target_: str = "parallax.coding.MultiScaleCoder"
    #: The scales in use, in this order in the state; [coarse] or [fine] is the single-scale
    #: ablation (§3.3 and its reference [4]).
    scales: list[str] = field(default_factory=lambda: ["coarse", "fine"])
    scale_specs: dict[str, ScaleSpecConfig] = field(default_factory=_paper_scales)
    #: N, basis functions per scale (§3.3).
    atoms: int = 288
    #: k, matching-pursuit steps: non-zero coefficients per patch (§3.3).
    sparsity: int = 10
    #: η of the dictionaries' gradient step on the reconstruction error (§3.3, after eq. 4; the
    #: paper gives no value): ΔΦ = η·R·Bᵀ/P.
    learning_rate: float = 0.01
    #: per_half: each eye's half of γ zero-mean and unit-norm (§3.3) | joint: the 200-vector.
    normalisation: str = "per_half"
    #: false freezes the dictionaries.
    learn: bool = True
    #: The image pairs coded: reference, (I0, I(t)) (§3.2) | consecutive, (I(t−1), I(t)), the
    #: retinal slip (beyond the paper; I(−1) is I0).
    pairing: str = "reference"
    #: B robots in lockstep (ROBOT_UPDATES): each (beyond the paper: the sum of every robot's own
    #: step, so every robot's patches teach in full) | mean (one step on the mean over all their
    #: patches, so B robots teach the dictionaries as much as one).
    robot_updates: str = "each"
    #: Filled by the trainer: the dictionaries' initialisation seed.
    seed: int = MISSING
    #: Filled by the trainer: env.image_size.
    image_size: int = MISSING


# --- the pursuit policy (policy/) ------------------------------------------------------------
@dataclass
class PolicyConfig:
    """Pursuit policy (§3.4, eqs. 5–8): natural actor-critic, Bhatnagar et al. 2009 algorithm 3,
    average reward, softmax over pan increments (step-size names as in NaturalActorCritic)."""

    _target_: str = "parallax.policy.NaturalActorCritic"
    #: Filled by the trainer: the coder's state size (2 scales × 288 bases = 576).
    state_dim: int = MISSING
    #: Filled by the trainer: the coder's number of scales.
    num_scales: int = MISSING
    #: The action set A, pan increments in degrees (§3.4).
    actions: list[float] = field(default_factory=lambda: list(ACTION_SET_DEG))
    #: α_v, the critic's step size (the paper gives no step sizes).
    critic_lr: float = 1.0
    #: α_n, the advantage weights' step size (the published pursuit setting: 0.025).
    advantage_lr: float = 0.1
    #: α_p, the actor's step size (published: 0.002, with which Θ approaches w/λ with the time
    #: constant 1/(α_p·λ) = 50 000 updates).
    actor_lr: float = 0.1
    #: ξ in δ = r − J + ξ·v·φ′ − v·φ (algorithm 3 has 1; 0.3 as in active-efficient-coding code).
    discount: float = 0.3
    #: ζ, the average reward's step size.
    reward_rate: float = 0.01
    #: λ, the actor's weight decay: at rest the logits are ≈ advantage/λ, so a smaller λ gives a
    #: sharper policy (published 0.01).
    weight_decay: float = 0.004
    #: T of the softmax, eq. (7).
    temperature: float = 1.0
    #: How θ becomes the features φ (parallax.policy.features): none (θ as in eq. 5) |
    #: l1_per_scale | zscore | centred_unit | zscore_unit | difference. difference (beyond the
    #: paper): θ(t) − θ(I0, I0), the state relative to the same stimulus at zero disparity,
    #: scaled to norm ≤ 1; it removes texture-dependent offsets.
    feature_norm: str = "difference"
    #: States (robots × steps) the running feature statistics of the normalisations beyond the
    #: paper remember, so that they follow the drifting pooled activities; 0: all of them.
    zscore_horizon: int = 20000
    #: Beyond the paper: d_ref (m) > 0 adds the eye's own position as one more feature,
    #: ν = tan(pan)·d_ref/l clipped to [−1, 1], so one weight can say "turned too far" (0: off).
    eye_position_reference_m: float = 0.5
    #: Beyond the paper: gain > 0 adds the last pan step's relative change of reward, signed by
    #: the step's direction, clip(gain·(r_t − r_{t−1})/|r_{t−1}|·sign(a_{t−1}), −1, 1), as one
    #: more feature: the reward peaks at α*, so it tells a linear policy which way the peak lies
    #: (0: off).
    reward_change_gain: float = 10.0
    #: Algorithm 3's projection Γ of the actor parameters Θ onto the ball of this radius after
    #: each update (Bhatnagar et al. 2009); null: no projection, the weight decay λ bounds Θ.
    actor_projection_radius: float | None = None
    #: B robots in lockstep (ROBOT_UPDATES): each (beyond the paper: their B updates one after
    #: the other, B steps of algorithm 3) | mean (the mean of their updates from the same
    #: parameters: the robots of a turn, env.robots_per_turn, teach as much as one).
    robot_updates: str = "each"
    #: Θ's entries start uniform in ±this (0: at zero). The paper gives no initialisation; the
    #: active-efficient-coding code starts the actor in ±0.4 (its weight_range).
    initial_actor_range: float = 0.0
    #: v's entries start uniform in ±this (0: at zero); the active-efficient-coding code: ±0.05.
    initial_critic_range: float = 0.0
    #: Whether the step into a trial, across the pan's reset to the trial's start, is learnt like
    #: any other within a presentation. The paper does not say; the active-efficient-coding code
    #: does not learn the first step of a trial.
    learn_reset_step: bool = False
    #: Filled by the trainer: seeds the action-sampling generator.
    seed: int = MISSING


# --- the distance learner (distance/) --------------------------------------------------------
@dataclass
class SensitivityConfig:
    """Which lateral positions are sensitive (§3.5.1, eq. 10, Table 1): disparity score at the
    nearest distance ≥ P_e − tolerance, with P_e = P_l·√P_s."""

    #: P_l, the patch side in pixels.
    patch: int = 10
    #: P_s of the coarse scale, so P_e = 10·√8 ≈ 28.3 px.
    subsample: float = 8.0
    #: Metres; Table 1's disparity scores are at 3 m.
    nearest_distance: float = 3.0
    #: Pixels below P_e still counted as sensitive: 15 cm (26.6 px) is, 14 cm (24.8 px) is not
    #: (the paper's "larger than or approximately equal to").
    tolerance: float = 2.5


@dataclass
class LevenbergMarquardtConfig:
    """The network's Levenberg–Marquardt fit (§3.5, [33]), with MATLAB trainlm's μ schedule."""

    #: μ, the damping the first step starts from (trainlm's mu).
    mu: float = 1.0e-3
    #: μ is multiplied by this after a step that lowered the error (trainlm's mu_dec).
    mu_decrease: float = 0.1
    #: μ is multiplied by this after a step that did not (trainlm's mu_inc).
    mu_increase: float = 10.0
    #: The fit stops when μ grows past this (trainlm's mu_max).
    mu_max: float = 1.0e10
    #: Stop when ‖Jᵀe‖ falls below this.
    min_grad: float = 1.0e-7
    #: Refuse larger models: the step solves a dense parameters × parameters system.
    max_params: int = 5000
    #: Refuse fits whose Jacobian (queued vectors × parameters) would be larger.
    max_jacobian_elements: int = 20_000_000
    #: Beyond trainlm: minimise Σe² + weight_decay·‖w‖² (w: all weights and biases, in the
    #: network's scaled units); a queue of c = 100 vectors and 541 parameters otherwise overfits
    #: (0: trainlm, the paper).
    weight_decay: float = 0.1


@dataclass
class OdometryConfig:
    """The robot's own measure of distance for distance.targets=odometry: strides counted on
    a walk to the panel (env.walk) times the stride length it believes it has."""

    #: Fraction of presentations that end with a walk (walking is costly); the others give the
    #: learner no target and are only predicted.
    walk_fraction: float = 1.0
    #: The stride length the robot believes it has (m): its unit of distance.
    nominal_stride_m: float = 0.05


@dataclass
class DistanceConfig:
    """Egocentric distance learner (§3.5–3.5.2, eqs. 9–15): queue memory, sensitive-position
    weighting, MLP r → hidden sigmoid → 1, trained by Levenberg–Marquardt."""

    _target_: str = "parallax.distance.DistanceLearner"
    #: Filled by the trainer: the lateral list L in metres (curriculum.lateral_positions).
    lateral_positions: list[float] = MISSING
    #: c, the queue memory's length (eq. 9; §4.2 uses 300).
    queue_size: int = 300
    #: Hidden sigmoid units (eqs. 13–14; §3.5.2 uses 30).
    hidden: int = 30
    #: Weigh the sensitive positions' inputs (eqs. 10–12); false: the plain inputs.
    weighting: bool = True
    #: y of eq. (12), w_k = 1/((1 + l_r − l_k)·y) with lengths in cm; the paper gives no value.
    y: float = 1.0
    sensitivity: SensitivityConfig = field(default_factory=SensitivityConfig)
    #: LM epochs each time a new s arrives (warm start); the paper trains "every iteration".
    epochs_per_call: int = 10
    #: LM epochs of the first fit, when the queue has just filled.
    initial_epochs: int = 100
    lm: LevenbergMarquardtConfig = field(default_factory=LevenbergMarquardtConfig)
    #: Where the targets come from (parallax.distance.targets.TARGET_SOURCES): supervisor, the
    #: true distances (§3.5) | odometry, beyond the paper (§7's second future work): the strides
    #: of the robot's own walk to the panel (``odometry``, env.walk).
    targets: str = "supervisor"
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    #: Fits start once the queue holds this many vectors; null: once it is full (§3.5). Fewer
    #: targets arrive when only some presentations are labelled (odometry.walk_fraction < 1).
    fit_from: int | None = None
    #: The network's input processing (parallax.distance.network.INPUT_SCALINGS): global, one
    #: mapminmax over all of S | per_input, MATLAB's mapminmax, each position scaled on its own
    #: (which cancels the weighting) | none, the pans as they are, a new network's initial
    #: weights spread over each input's range (MATLAB's initnw).
    input_scaling: str = "global"
    #: Share of the queue each fit holds out to stop on (MATLAB's dividerand; 0: none): the fit
    #: stops after ``max_fail`` epochs in a row whose error on these vectors rose, and keeps the
    #: weights of its best epoch, as MATLAB's train does.
    validation_fraction: float = 0.0
    #: Share of the queue each fit leaves out altogether (dividerand's test set; 0: none).
    test_fraction: float = 0.0
    #: Epochs in a row with a rising validation error that stop a fit (MATLAB's max_fail).
    max_fail: int = 6
    #: Start every fit from lm.mu, as each call of MATLAB's train does; false: carry μ over
    #: from the last fit (the queue changes by one vector).
    reset_mu: bool = False
    #: Each fit starts from the last fit's weights, as calling MATLAB's train again on the same
    #: network does; false: from new random weights each time (a program that builds its
    #: network again before each call), for ``initial_epochs``.
    warm_start: bool = True
    #: With a warm start, keep the [−1, 1] scaling of the first fit, as MATLAB's train does (it
    #: configures mapminmax only on a network not yet configured); false: refit it to each fit's
    #: queue, the weights re-expressed so that the network's function is unchanged.
    keep_first_scaling: bool = False
    #: What reads a distance from s, one of parallax/distance/estimators/: network, the MLP
    #: above (eqs. 13–15), as in the paper.
    estimator: str = "network"
    #: Filled by the trainer: the network's initialisation seed.
    seed: int = MISSING


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


# --- the robustness test (perturbation/) -----------------------------------------------------
@dataclass
class PerturbationConfig:
    """The robustness test of §5: the left camera rotated and its images blurred while training
    goes on."""

    #: Rotation of the left camera in degrees (§5: 15).
    camera_rotation_deg: float = 0.0
    #: optical | horizontal | vertical, or a 3-vector in the camera frame.
    rotation_axis: Any = "optical"
    #: σ of the Gaussian blur in pixels (§5: 2).
    blur_sigma: float = 0.0
    #: Fraction of train.presentations after which the perturbation is switched on; null: never.
    start_fraction: float | None = None


# --- how the robot moves (top level) ---------------------------------------------------------
@dataclass
class MovementConfig:
    """Beyond the paper (its first future work, §7): the robot chooses where to move next and
    when to stop (parallax.distance.planner), instead of sweeping all of L."""

    #: list: every position of L in order, every presentation (the paper) | planned: the robot
    #: plans its route from its confidence (one robot, supervisor targets).
    route: str = "list"
    #: planned: what one trial (t_h eye movements) costs, in percentage points of expected
    #: distance error.
    price_per_trial: float = 0.1
    #: planned: what one centimetre of lateral travel (out to the farthest position and back)
    #: costs, in percentage points of expected distance error.
    price_per_cm: float = 0.0
    #: planned: the probability that a training presentation sweeps all of L instead; the
    #: planner and the distance network learn from those sweeps (and every presentation sweeps
    #: until the planner's queue of c sweeps is full).
    explore: float = 0.25


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


def default(node: type, name: str) -> Any:
    """The schema's default of ``node``'s setting ``name``, for a component's keyword default:
    lists as tuples and nodes as read-only mappings, so that one default object can be shared by
    every call. Plain values can be read off the class as well (``CoderConfig.atoms``)."""
    spec = next(spec for spec in dataclasses.fields(node) if spec.name == name)
    value = spec.default_factory() if spec.default is dataclasses.MISSING else spec.default
    return _read_only(value)


def _read_only(value: Any) -> Any:
    if dataclasses.is_dataclass(value):
        value = {spec.name: getattr(value, spec.name) for spec in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return MappingProxyType({key: _read_only(item) for key, item in value.items()})
    if isinstance(value, list):
        return tuple(_read_only(item) for item in value)
    return value
